"""Read SDL text into a :class:`tracer.model.Scene`.

The reader is one loop over statements.  Two things make SDL more than a flat list:

* ``use name`` splices a macro body into the input.  The token source is therefore a stack of frames (the
  file, then each macro body being read); the names of the frames on the stack are the macros being
  expanded, which gives shapes their ``groups`` and lets ``use`` refuse a macro that uses itself.
* ``union``/``intersection``/``difference`` take the next two *objects*.  Rather than recursing, the reader
  keeps a stack of booleans still waiting for operands and hands every finished object to the innermost one.

Neither needs Python recursion, so deep nesting in a file cannot crash the reader.

A file of 10^5 shapes is some 1.5·10^6 tokens in 6·10^5 statements, so the per-statement work is kept to
plain Python values: tokens are strings, each known by its number in the file (lexer.Tokens splits the file a
block of lines at a time), and a token's line and column are found only for what is kept or reported (a
shape's source, an error); a statement's numbers are converted together; the current transform is 12 floats
(transforms.Affine), made a matrix once per shape; equal materials are one Material.

Errors come in two kinds.  *Syntax* problems (a word where a number belongs, an unknown keyword) abandon the
statement: in strict mode they raise :class:`SDLError`; in lenient mode they become one warning and reading
resumes at the next keyword.  *Semantic* problems (a missing mesh file, ``pop`` with nothing pushed) are found
after the statement has been read whole: strict mode raises, lenient mode warns and carries on without that
statement or shape.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Callable, Iterator, Optional, Sequence, Union

import numpy as np

from .. import shapes, transforms
from ..bulk import collector_paused
from ..camera import camera_problem
from ..errors import SDLError
from ..geometry import builtin_mesh  # (its home; imported under this name by the add-on and tests)
from ..meshio import read_3vn
from ..model import (ANALYTIC_KINDS, CSG, FRESNEL_MODES, MAX_RECURSION_DEPTH, POLYHEDRON_KINDS, SHAPE_KINDS, Camera, Light,
                     Material, MeshData, Scene, SceneObject, Shape, SourceLocation, TEXTURE_NUMBERS)
from ..userfiles import read_text
from .lexer import Tokens, to_float, to_floats
from .lights import LIGHT_USAGE, argument_count, light_of
# (the writer reads COLOR_MATERIAL and FLOAT_MATERIAL here)
from .statements import COLOR_MATERIAL, FLOAT_MATERIAL, MAX_PARAMETERS, STATEMENTS  # noqa: F401

PathLike = Union[str, "os.PathLike[str]"]

# ---------------------------------------------------------------------------------------------------------
# Keyword tables (tracer/sdl/statements.py has every statement; the writer uses them too, so that both sides
# agree on spelling).

#: Image numbers ``makePixmap`` accepts.
PIXMAP_RANGE = range(16)
CSG_OPS = CSG.OPS

#: Every keyword with the arguments it takes, for messages ("expected 'translate dx dy dz'").
USAGE: dict[str, str] = {s.keyword: s.usage for s in STATEMENTS}
KEYWORDS = frozenset(USAGE)
#: The keywords of the extensions for Blender scenes (not the book's; their own tests use them).
EXTENSION_KEYWORDS = frozenset(s.keyword for s in STATEMENTS if s.extension and s.keyword not in SHAPE_KINDS)
#: The statements that add a light (a name comment names them as it names shapes).
LIGHT_KEYWORDS = ("light", *LIGHT_USAGE)

#: A guard against macros that do not recurse but still multiply (each using the previous one twice, thirty
#: deep, is a billion tokens): no real scene splices anywhere near this many tokens.
MAX_SPLICED_TOKENS = 2_000_000

#: Texts at least this long are offered to the C core's reader first (parse_sdl): below it, the C side's
#: set-up costs more than it saves.
FAST_MIN_CHARS = 1 << 16

#: A transform whose linear part is this badly conditioned is treated as singular (e.g. ``scale 1 1 0``).
MAX_CONDITION = 1e12


# ---------------------------------------------------------------------------------------------------------
# Token source with macro splicing.

class _Frame:
    """The file (its current block of tokens), or the body of one macro while ``use`` splices it in.

    ``numbers`` gives each token's number in the file (see lexer.Tokens): its place, for messages."""

    __slots__ = ("tokens", "numbers", "macro", "pos")

    def __init__(self, tokens: list[str], numbers: Sequence[int], macro: Optional[str]):
        self.tokens = tokens
        self.numbers = numbers
        self.macro = macro
        self.pos = 0


class _TokenSource:
    """The tokens to read next: the file's, with the bodies of the macros being expanded spliced in.

    The file's tokens come from the lexer a block at a time; ``on_block(tokens, first number)`` sees each
    block before any of its tokens is read.

    The names of the open macros are kept alongside the frames (a list, a count per name and the tuple
    handed out as a shape's groups, rebuilt only when a macro opens or closes), so that asking for them, or
    whether a name is open, costs the same at any nesting depth: a chain of 20,000 macros each using the
    next reads in linear time."""

    def __init__(self, lexed: Tokens, on_block: Callable[[list[str], int], None]):
        self._lexed = lexed
        self._on_block = on_block
        self._frames = [_Frame([], range(0), None)]
        self._spliced = 0
        self._names: list[str] = []
        self._open: dict[str, int] = {}
        self._groups: Optional[tuple[str, ...]] = ()
        #: The number of the token :meth:`next` returned last.
        self.last = -1

    def _settle(self) -> None:
        # A finished macro frame is dropped only when the *next* token is wanted, so that right after reading
        # a macro's last token (a shape keyword, or the name in a final ``use``) that macro still counts as
        # being expanded: the shape is in its group, and ``use`` sees the whole chain.
        frames = self._frames
        while frames[-1].pos >= len(frames[-1].tokens):
            if len(frames) > 1:
                name = frames.pop().macro
                self._names.pop()
                self._open[name] -= 1
                self._groups = None
                continue
            first = self._lexed.count
            block = self._lexed.next_block()
            if block is None:
                return
            self._on_block(block, first)
            file = frames[0]
            file.tokens, file.numbers, file.pos = block, range(first, first + len(block)), 0

    def peek(self) -> Optional[str]:
        # The common case first: the top frame has tokens left, so there is nothing to settle (a scene of
        # 10,000 shapes peeks 240,000 times).
        top = self._frames[-1]
        if top.pos < len(top.tokens):
            return top.tokens[top.pos]
        self._settle()
        top = self._frames[-1]
        return top.tokens[top.pos] if top.pos < len(top.tokens) else None

    def next(self) -> Optional[str]:
        token = self.peek()
        if token is not None:
            top = self._frames[-1]
            self.last = top.numbers[top.pos]
            top.pos += 1
        return token

    def take_numbers(self, count: int) -> Optional[tuple[float, ...]]:
        """The next ``count`` tokens as numbers (read), if the top frame holds them all and all are numbers
        (then nothing needs settling between them); else None, and nothing is read."""
        top = self._frames[-1]
        end = top.pos + count
        if end <= len(top.tokens):
            values = to_floats(top.tokens[top.pos:end])
            if values is not None:
                top.pos = end
                return values
        return None

    def number_ahead(self) -> int:
        """The number of the token :meth:`peek` returned."""
        top = self._frames[-1]
        return top.numbers[top.pos]

    def keywords(self) -> Iterator[tuple[str, int, tuple[str, ...]]]:
        """The tokens that start statements: each with its number and the macros open when it was read.
        Its statement reads the rest of itself from this source before the next is asked for."""
        frames = self._frames
        while True:
            top = frames[-1]
            pos = top.pos
            if pos < len(top.tokens):  # the common case, inline: nothing to settle
                top.pos = pos + 1
                self.last = top.numbers[pos]
                yield top.tokens[pos], self.last, self._groups if self._groups is not None else self.macros()
            elif (token := self.next()) is not None:
                yield token, self.last, self.macros()
            else:
                return

    def macros(self) -> tuple[str, ...]:
        """Names of the macros being expanded, outermost first."""
        if self._groups is None:
            self._groups = tuple(self._names)
        return self._groups

    def in_macro(self) -> bool:
        """Whether a macro body is being read (a token read from the file itself always answers False)."""
        return len(self._frames) > 1

    def is_open(self, name: str) -> bool:
        """Whether macro ``name`` is being expanded (then using it again would never end)."""
        return self._open.get(name, 0) > 0

    def chain_from(self, name: str) -> tuple[str, ...]:
        """The open macros from the outermost ``name`` inwards."""
        return tuple(self._names[self._names.index(name):])

    @property
    def spliced(self) -> int:
        """Tokens spliced in so far."""
        return self._spliced

    def splice(self, name: str, macro: "_Macro") -> None:
        """Read the body of ``macro`` next (the caller has checked the expansion budget)."""
        self._spliced += len(macro.body)
        self._frames.append(_Frame(macro.body, macro.numbers, name))
        self._names.append(name)
        self._open[name] = self._open.get(name, 0) + 1
        self._groups = None


@dataclass
class _PendingBoolean:
    """A boolean whose operands are still being read; an operand of None was dropped (lenient mode)."""

    op: str
    at: int  # the number of its keyword
    groups: tuple[str, ...]
    children: list[Optional[SceneObject]] = field(default_factory=list)


@dataclass
class _Macro:
    body: list[str]
    numbers: Sequence[int]  # of the body's tokens
    at: int  # the number of its name in the def, for messages


#: Statements a name comment does not reach past: it names a shape read directly after it, not one in a macro.
_NAME_STOPS = frozenset(("def", "use", "{", "}"))
#: What a name comment names (a set: looked up for every token between a name and its shape or light).
_NAMED_KEYWORDS = frozenset(SHAPE_KINDS + LIGHT_KEYWORDS)


class _ShapeNames:
    """Which shape each ``! name:`` comment names: the number of a shape keyword -> its name.

    A comment names the first shape keyword after it, unless a def, use or brace comes first; a later comment
    before the same shape wins.  A named shape inside a def body is named wherever the macro is used.
    Worked out a block of tokens at a time, as the lexer splits them; a comment whose shape is in a later
    block waits for it."""

    def __init__(self):
        self.names: dict[int, str] = {}
        self._waiting: Optional[tuple[int, str]] = None

    def add_block(self, tokens: list[str], first: int, comments: list[tuple[int, str]]) -> None:
        """Names for the shapes in ``tokens`` (numbered from ``first``) from the name comments among them
        (``comments``) and the one still waiting."""
        if self._waiting is not None:
            comments = [self._waiting] + comments
            self._waiting = None
        ends = [number for number, _ in comments[1:]] + [first + len(tokens)]
        for (number, name), end in zip(comments, ends):
            # Looked for only up to the next comment: past it, that comment's name wins anyway.
            for index in range(number - first, end - first):
                token = tokens[index]
                if token in _NAMED_KEYWORDS:
                    self.names[first + index] = name
                    break
                if token in _NAME_STOPS:
                    break
            else:
                if end == first + len(tokens):
                    self._waiting = (end, name)


# ---------------------------------------------------------------------------------------------------------

#: Material field -> default value, in the dataclass's order (the reader keeps the current material so).
_MATERIAL_DEFAULTS = {f.name: getattr(Material(), f.name) for f in fields(Material)}


class _Reader:
    def __init__(self, text: str, base_dir: Optional[PathLike], file: Optional[str], strict: bool):
        self.file = file
        self.base_dir = Path(base_dir) if base_dir is not None else None
        self.strict = strict
        self.tokens = Tokens(text)
        self.shape_names = _ShapeNames()
        self.source = _TokenSource(self.tokens, self._new_block)
        self.scene = Scene()
        # The current material as its fields (a statement sets one in place) and, once a shape needed it,
        # as a Material; equal materials are one object (10^5 shapes in a few colours keep a few).
        self.material_fields = dict(_MATERIAL_DEFAULTS)
        self.material: Optional[Material] = None
        self.materials: dict[tuple, Material] = {}
        self.stack: list[transforms.Affine] = [transforms.IDENTITY_AFFINE]
        self.invertible: Optional[transforms.Affine] = None  # the transform last found to have an inverse
        self.macros: dict[str, _Macro] = {}
        self.macro_sizes: dict[str, int] = {}  # tokens a use of each macro splices (see _expanded_size)
        self.pending: list[_PendingBoolean] = []
        self.mesh_cache: dict[str, MeshData] = {}
        self.macro_locations: dict[int, SourceLocation] = {}  # shapes in macro bodies: one per body token
        self.reported: set[str] = set()
        self.handlers: dict[str, Callable[[str, int, tuple[str, ...]], None]] = {
            s.keyword: getattr(self, s.handler) for s in STATEMENTS}

    def _new_block(self, tokens: list[str], first: int) -> None:
        self.shape_names.add_block(tokens, first, self.tokens.name_comments)

    # -- driving loop -----------------------------------------------------------------------------------

    def read(self) -> Scene:
        handlers = self.handlers
        for keyword, at, groups in self.source.keywords():
            try:
                handler = handlers.get(keyword)
                if handler is None:
                    raise self._unknown(keyword, at)
                handler(keyword, at, groups)
            except SDLError as error:
                self._report(error)
                self._resync()
        self._finish_booleans()
        return self.scene

    def _report(self, error: SDLError) -> None:
        """Strict: raise.  Lenient: keep the message and let the caller carry on."""
        if self.strict:
            raise error
        self._note(error)

    def _note(self, error: SDLError) -> None:
        """Something read, but not as written (a value beyond a limit): a warning, strict or not.  The same
        message met again (a typo inside a macro used ten times) is still one problem."""
        message = str(error)
        if message not in self.reported:
            self.reported.add(message)
            self.scene.warnings.append(message)

    def _resync(self) -> None:
        # After a broken statement, skip its leftovers quietly up to the next keyword, so that one mistake
        # gives one warning rather than one per stray word.
        while (token := self.source.peek()) is not None and token not in KEYWORDS:
            self.source.next()

    # -- building errors --------------------------------------------------------------------------------

    def _error(self, at: int, message: str, expected: Optional[str] = None, show_token: bool = True) -> SDLError:
        """An error pointing at token number ``at``."""
        token = self.tokens.locate(at)
        return SDLError(message, file=self.file, line=token.line, column=token.column,
                        token=token.text if show_token else None, expected=expected)

    def _end_of_file(self, keyword: str, at: int, expected: str) -> SDLError:
        # Pointing at the statement that was cut short helps more than pointing past the last line.
        return self._error(at, f"end of file inside the '{keyword}' statement", expected=expected, show_token=False)

    @staticmethod
    def _usage(keyword: str) -> str:
        args = USAGE.get(keyword, "")
        return f"'{keyword} {args}'" if args else f"'{keyword}'"

    def _unknown(self, text: str, at: int) -> SDLError:
        if text == "}":
            return self._error(at, "unbalanced '}': no '{' is open")
        if text == "{":
            return self._error(at, "'{' outside a def", expected="'def name { ... }'")
        if to_float(text) is not None:
            return self._error(at, "a number where a keyword belongs (too many numbers?)", expected="a keyword")
        if text in self.macros:
            return self._error(at, f"unknown keyword; to expand the macro write 'use {text}'")
        import difflib  # (only for a file with a mistake: a render that reads well never loads it)

        # Keywords are case-sensitive; a wrong case is the likeliest typo of all.
        suggestion = [k for k in KEYWORDS if k.lower() == text.lower()] or \
            difflib.get_close_matches(text, sorted(KEYWORDS), n=1, cutoff=0.7)
        if suggestion:
            return self._error(at, f"unknown keyword, did you mean '{suggestion[0]}'?")
        return self._error(at, "unknown keyword", expected="a keyword")

    # -- reading arguments --------------------------------------------------------------------------------

    def _number_token(self, keyword: str, at: int) -> tuple[float, int]:
        """The next token as a number, and its number (place)."""
        token = self.source.peek()
        if token is None:
            raise self._end_of_file(keyword, at, self._usage(keyword))
        value = to_float(token)
        if value is None:
            # Left unread: if it is a keyword, reading resumes with it (lenient mode).
            raise self._error(self.source.number_ahead(), f"expected a number after '{keyword}'",
                              expected=self._usage(keyword))
        self.source.next()
        return value, self.source.last

    def _numbers(self, keyword: str, at: int, count: int) -> tuple[float, ...]:
        values = self.source.take_numbers(count)
        if values is None:  # a word that is no number, or a macro or block ends first: one by one
            values = tuple(self._number_token(keyword, at)[0] for _ in range(count))
        return values

    def _name(self, keyword: str, at: int, what: str) -> tuple[str, int]:
        """A file or macro name: any word that is not a brace or a keyword; and its number (place)."""
        token = self.source.peek()
        if token is None:
            raise self._end_of_file(keyword, at, self._usage(keyword))
        if token in ("{", "}") or token in KEYWORDS:
            raise self._error(self.source.number_ahead(), f"expected {what} after '{keyword}'",
                              expected=self._usage(keyword))
        self.source.next()
        return token, self.source.last

    def _location(self, at: int) -> SourceLocation:
        return SourceLocation(self.file, *self.tokens.place(at))

    # -- scene settings ---------------------------------------------------------------------------------

    def _light(self, keyword: str, at: int, groups) -> None:
        x, y, z, r, g, b = self._numbers(keyword, at, 6)
        self.scene.lights.append(Light((x, y, z), (r, g, b), name=self.shape_names.names.get(at)))

    def _physical_light(self, keyword: str, at: int, groups) -> None:
        light = light_of(keyword, self._numbers(keyword, at, argument_count(keyword)),
                         self.shape_names.names.get(at))
        if isinstance(light, str):
            return self._report(self._error(at, f"{keyword}: {light}", expected=self._usage(keyword)))
        self.scene.lights.append(light)

    def _smooth_terminator(self, keyword: str, at: int, groups) -> None:
        value, number = self._number_token(keyword, at)
        if value not in (0.0, 1.0):
            return self._report(self._error(number, "smoothTerminator must be 0 or 1"))
        self.scene.settings.smooth_terminator = value == 1.0

    def _global_ambient(self, keyword: str, at: int, groups) -> None:
        self.scene.settings.global_ambient = self._numbers(keyword, at, 3)

    def _background(self, keyword: str, at: int, groups) -> None:
        self.scene.settings.background = self._numbers(keyword, at, 3)

    def _min_reflectivity(self, keyword: str, at: int, groups) -> None:
        self.scene.settings.min_reflectivity = self._numbers(keyword, at, 1)[0]

    def _min_transparency(self, keyword: str, at: int, groups) -> None:
        self.scene.settings.min_transparency = self._numbers(keyword, at, 1)[0]

    def _max_recursion_depth(self, keyword: str, at: int, groups) -> None:
        value, number = self._number_token(keyword, at)
        if not value.is_integer() or value < 0:
            return self._report(self._error(number, "maxRecursionDepth must be a whole number >= 0"))
        if value > MAX_RECURSION_DEPTH:  # read, in strict mode too: a deep setting is no mistake
            self._note(self._error(number, f"maxRecursionDepth is more than the tracer follows: "
                                           f"{MAX_RECURSION_DEPTH} used"))
            value = MAX_RECURSION_DEPTH
        self.scene.settings.max_recursion_depth = int(value)

    def _make_pixmap(self, keyword: str, at: int, groups) -> None:
        index, index_number = self._number_token(keyword, at)
        name, _ = self._name(keyword, at, "an image file name")
        if not index.is_integer() or int(index) not in PIXMAP_RANGE:
            return self._report(self._error(
                index_number, "makePixmap image number out of range",
                expected=f"a whole number {PIXMAP_RANGE.start}..{PIXMAP_RANGE.stop - 1}"))
        self.scene.pixmaps[int(index)] = str(self._resolve(name))
        self.scene.pixmap_sources[int(index)] = self._location(at)

    def _camera(self, keyword: str, at: int, groups) -> None:
        numbers = self._numbers(keyword, at, 10)
        eye, look, up = numbers[0:3], numbers[3:6], numbers[6:9]
        angle = numbers[9]
        problem = camera_problem(eye, look, up, angle)
        if problem:
            return self._report(self._error(at, problem))
        self.scene.camera = Camera(eye=eye, look=look, up=up, view_angle=angle)

    # -- material ---------------------------------------------------------------------------------------

    def _set_material(self, name: str, value) -> None:
        self.material_fields[name] = value
        self.material = None

    def _current_material(self) -> Material:
        """The material that the statements so far give, as one Material per distinct value."""
        if self.material is None:
            key = tuple(self.material_fields.values())
            self.material = self.materials.get(key)
            if self.material is None:
                self.material = self.materials[key] = Material(*key)
        return self.material

    def _color_material(self, keyword: str, at: int, groups) -> None:
        self._set_material(COLOR_MATERIAL[keyword], self._numbers(keyword, at, 3))

    def _float_material(self, keyword: str, at: int, groups) -> None:
        self._set_material(FLOAT_MATERIAL[keyword], self._numbers(keyword, at, 1)[0])

    def _fresnel(self, keyword: str, at: int, groups) -> None:
        mode, number = self._name(keyword, at, "a fresnel mode")
        if mode not in FRESNEL_MODES:
            return self._report(self._error(number, "unknown fresnel mode", expected=" or ".join(FRESNEL_MODES)))
        self._set_material("fresnel", mode)

    def _fresnel_tint(self, keyword: str, at: int, groups) -> None:
        self._set_material("fresnel_tint", self._numbers(keyword, at, 3))

    def _texture(self, keyword: str, at: int, groups) -> None:
        value, number = self._number_token(keyword, at)
        if not value.is_integer():
            return self._report(self._error(number, "texture number must be a whole number"))
        if int(value) not in TEXTURE_NUMBERS:
            return self._report(self._error(number, "texture number out of range",
                                            expected="-1, -2, -3 or a makePixmap number"))
        self._set_material("texture", int(value))

    def _parameters(self, keyword: str, at: int, groups) -> None:
        count, count_number = self._number_token(keyword, at)
        if not count.is_integer() or count < 0:
            raise self._error(count_number, "expected how many parameters follow",
                              expected=f"a whole number 0..{MAX_PARAMETERS}")
        count = int(count)
        if count <= MAX_PARAMETERS:
            self._set_material("parameters", self._numbers(keyword, at, count))
            return
        # Too many: warn once, read the numbers that are there (up to the count) and keep the first ten.
        self._report(self._error(count_number, f"parameters takes at most {MAX_PARAMETERS} numbers",
                                 expected=f"a whole number 0..{MAX_PARAMETERS}"))
        values = []
        while len(values) < count and (token := self.source.peek()) is not None and to_float(token) is not None:
            values.append(to_float(self.source.next()))
        self._set_material("parameters", tuple(values[:MAX_PARAMETERS]))

    def _default_materials(self, keyword: str, at: int, groups) -> None:
        self.material_fields = dict(_MATERIAL_DEFAULTS)
        self.material = None

    # -- transforms -------------------------------------------------------------------------------------
    # Post-multiplied: the statement written last acts on the shape first (M = T·S for "translate scale").

    def _translate(self, keyword: str, at: int, groups) -> None:
        self.stack[-1] = transforms.affine_translate(self.stack[-1], *self._numbers(keyword, at, 3))

    def _scale(self, keyword: str, at: int, groups) -> None:
        self.stack[-1] = transforms.affine_scale(self.stack[-1], *self._numbers(keyword, at, 3))

    def _rotate(self, keyword: str, at: int, groups) -> None:
        angle = self._number_token(keyword, at)[0]
        axis = [self._number_token(keyword, at) for _ in range(3)]
        try:
            matrix = transforms.rotation(angle, *(value for value, _ in axis))
        except ValueError:
            first = self.tokens.locate(axis[0][1])
            return self._report(SDLError(
                "rotate needs a non-zero axis", file=self.file, line=first.line, column=first.column,
                token=" ".join(self.tokens.locate(number).text for _, number in axis),
                expected="'rotate angle ux uy uz', axis not 0 0 0"))
        self.stack[-1] = transforms.affine_times(self.stack[-1], matrix)

    def _push(self, keyword: str, at: int, groups) -> None:
        self.stack.append(self.stack[-1])  # a tuple: the copy and the original never change

    def _pop(self, keyword: str, at: int, groups) -> None:
        if len(self.stack) == 1:  # the base transform always stays
            return self._report(self._error(at, "pop without a matching push"))
        self.stack.pop()

    def _identity(self, keyword: str, at: int, groups) -> None:
        self.stack[-1] = transforms.IDENTITY_AFFINE

    # -- objects ----------------------------------------------------------------------------------------

    def _place(self, obj: Optional[SceneObject]) -> None:
        """Give a finished object to the innermost waiting boolean, or to the scene."""
        while self.pending:
            boolean = self.pending[-1]
            boolean.children.append(obj)
            if len(boolean.children) < 2:
                return
            self.pending.pop()
            obj = self._combine(boolean)
        if obj is not None:
            self.scene.objects.append(obj)

    def _combine(self, boolean: _PendingBoolean) -> Optional[SceneObject]:
        children = [c for c in boolean.children if c is not None]
        if len(children) == 2:
            return CSG(boolean.op, children[0], children[1], groups=boolean.groups, source=self._location(boolean.at))
        # An operand was dropped (lenient mode): the boolean degrades to what is left.
        return children[0] if children else None

    def _boolean(self, keyword: str, at: int, groups) -> None:
        self.pending.append(_PendingBoolean(keyword, at, groups))

    def _finish_booleans(self) -> None:
        while self.pending:
            boolean = self.pending.pop()
            op = boolean.op
            self._report(self._error(boolean.at, f"end of file: '{op}' needs two objects, found "
                                                 f"{len(boolean.children)}", expected=f"'{op} object object'",
                                     show_token=False))
            self._place(self._combine(boolean))

    def _shape(self, keyword: str, at: int, groups) -> None:
        try:
            shape = self._read_shape(keyword, at, groups)
        except SDLError:
            self._place(None)  # a broken operand still fills its place in a boolean
            raise
        self._place(shape)

    def _read_shape(self, kind: str, at: int, groups) -> Optional[Shape]:
        entry = shapes.KINDS[kind]
        parameters, mesh_file = tuple(self._number_token(kind, at)[0] for _ in entry.parameters), None
        if entry.file_argument:
            mesh_file, mesh_at = self._name(kind, at, "a mesh file name")
        transform = self.stack[-1]
        if transform is not self.invertible:  # (shapes in a row often share their transform)
            if _affine_is_singular(transform):
                overflows = not all(map(math.isfinite, transform))
                why = "transform overflows" if overflows else "singular transform"
                hint = "scales too large for a float" if overflows else "a scale of 0?"
                self._report(self._error(at, f"{why} for '{kind}' ({hint})", expected="a transform with an inverse"))
                return None
            self.invertible = transform
        mesh = None
        if entry.file_argument:
            mesh = self._mesh_file(mesh_file, mesh_at)
            if mesh is None:
                return None
        elif entry.builtin_mesh:
            mesh = builtin_mesh(kind)
        # (The 16 entries, not a matrix: Shape makes its own matrix of what it is given anyway.)
        return Shape(_SHAPE_KIND[kind], transforms.affine_entries(transform), self._current_material(),
                     parameters, mesh, mesh_file, groups, self._shape_location(at),
                     self.shape_names.names.get(at))

    def _shape_location(self, at: int) -> SourceLocation:
        if not self.source.in_macro():
            return self._location(at)
        # A macro used many times places its shapes at the same token each time: one location for all (a
        # shape that is a macro's last token may come here or above; either way its place is the same).
        location = self.macro_locations.get(at)
        if location is None:
            location = self.macro_locations[at] = self._location(at)
        return location

    def _resolve(self, name: str) -> Path:
        return self.base_dir / name if self.base_dir is not None else Path(name)

    def _mesh_file(self, name: str, at: int) -> Optional[MeshData]:
        """The mesh a ``mesh`` statement names (read once per file), or None after reporting a problem."""
        path = self._resolve(name)
        key = os.path.normpath(os.path.abspath(path))
        if key in self.mesh_cache:
            return self.mesh_cache[key]
        if not path.is_file():
            self._report(self._error(at, f"mesh file not found: {path}", expected="an existing .3vn file"))
            return None
        try:
            mesh = read_3vn(path)
        except SDLError as inner:
            # The inner message names the .3vn file, its line and the bad word.
            self._report(self._error(at, f"bad mesh file: {inner}", show_token=False))
            return None
        self.mesh_cache[key] = mesh
        return mesh

    # -- macros -----------------------------------------------------------------------------------------

    def _def(self, keyword: str, at: int, groups) -> None:
        name, name_at = self._name(keyword, at, "a macro name")
        brace = self.source.peek()
        if brace is None:
            raise self._end_of_file(keyword, at, self._usage(keyword))
        if brace != "{":
            raise self._error(self.source.number_ahead(), f"expected '{{' after 'def {name}'",
                              expected=self._usage(keyword))
        self.source.next()
        body: list[str] = []
        numbers: list[int] = []
        depth = 1  # braces nest (the book's body ends at the first '}')
        while True:
            token = self.source.next()
            if token is None:
                self.macros.setdefault(name, _Macro(body, _compact(numbers), name_at))  # lenient mode keeps it
                raise self._error(at, f"end of file inside the body of 'def {name}'", expected="'}'", show_token=False)
            depth += {"{": 1, "}": -1}.get(token, 0)
            if depth == 0:
                break
            body.append(token)
            numbers.append(self.source.last)
        self._define(name, name_at, _Macro(body, _compact(numbers), name_at))

    def _define(self, name: str, at: int, macro: _Macro) -> None:
        earlier = self.macros.get(name)
        self.macros[name] = macro  # lenient mode: the later definition wins
        self.macro_sizes.clear()  # sizes of macros that use this name may change
        if earlier is not None:
            self._report(self._error(at, f"macro '{name}' is already defined "
                                         f"(line {self.tokens.locate(earlier.at).line})"))

    def _use(self, keyword: str, at: int, groups) -> None:
        name, name_at = self._name(keyword, at, "a macro name")
        macro = self.macros.get(name)
        if macro is None:
            import difflib

            close = difflib.get_close_matches(name, sorted(self.macros), n=1, cutoff=0.7)
            hint = f", did you mean '{close[0]}'?" if close else ""
            raise self._error(name_at, f"undefined macro{hint}", expected="a name given by an earlier def")
        if self.source.is_open(name):
            chain = self.source.chain_from(name) + (name,)
            raise self._error(name_at, f"macro '{name}' uses itself: {_chain(chain)}")
        size = self._expanded_size(name)
        if self.source.spliced + size > MAX_SPLICED_TOKENS:
            chain = self.source.macros() + self._growth(name)
            raise self._error(name_at, f"'use {_cut_name(name)}' would splice {size:,} tokens "
                                       f"({_chain(chain)}), more than the {MAX_SPLICED_TOKENS:,} that macros "
                                       f"may expand to in one file", show_token=False)
        self.source.splice(name, macro)

    def _growth(self, name: str) -> tuple[str, ...]:
        """``name`` and, from it down, the macro each one uses that expands to the most: where a budget went."""
        chain, seen = [name], {name}
        while (macro := self.macros.get(chain[-1])) is not None:
            used = [u for u in _used_macros(macro.body) if u not in seen and u in self.macros]
            if not used:
                break
            chain.append(max(used, key=self._expanded_size))
            seen.add(chain[-1])
        return tuple(chain)

    def _expanded_size(self, name: str) -> int:
        """How many tokens ``use name`` splices in all, its macros' macros included: computed before
        anything is expanded, from the bodies (memoised per definition; without recursion, so a chain of any
        length is fine).  A macro that uses itself counts once here; expanding it is an error anyway."""
        sizes = self.macro_sizes
        if name in sizes:
            return sizes[name]
        stack, visiting = [name], set()
        while stack:
            current = stack[-1]
            if current in sizes:
                stack.pop()
                continue
            macro = self.macros.get(current)
            if macro is None:
                sizes[current] = 0
                stack.pop()
                continue
            used = _used_macros(macro.body)
            pending = [u for u in used if u not in sizes and u not in visiting and u in self.macros]
            if current not in visiting and pending:
                visiting.add(current)
                stack.extend(pending)
                continue
            visiting.discard(current)
            # A self-use still unknown counts as nothing; the size saturates far above any budget.
            total = len(macro.body) + sum(sizes.get(u, 0) for u in used)
            sizes[current] = min(total, 1 << 62)
            stack.pop()
        return sizes[name]


def _used_macros(body: list[str]) -> list[str]:
    """The names after each ``use`` in a macro body."""
    return [word for before, word in zip(body, body[1:]) if before == "use"]


def _compact(numbers: list[int]) -> Sequence[int]:
    """Token numbers as a range when they follow one another (a body read straight from the file: nearly
    always), else the list."""
    if numbers and numbers[-1] - numbers[0] == len(numbers) - 1 and \
            numbers == list(range(numbers[0], numbers[-1] + 1)):
        return range(numbers[0], numbers[-1] + 1)
    return numbers


#: The one string of each shape keyword: a shape's kind is that, not the token's own copy.
_SHAPE_KIND = {kind: kind for kind in SHAPE_KINDS}


def _cut_name(name: str) -> str:
    return name if len(name) <= 40 else name[:40] + "..."


def _chain(names: tuple[str, ...], shown: int = 6) -> str:
    """A chain of macro names for a message; a long one shows its two ends."""
    names = tuple(_cut_name(n) for n in names)
    if len(names) > shown:
        names = names[:shown // 2] + (f"... {len(names) - shown} more ...",) + names[-(shown // 2):]
    return " -> ".join(names)


def _clearly_invertible(matrix: np.ndarray) -> bool:
    """A cheap, pure-Python sufficient condition for is_singular(matrix) to be False.

    With all 16 entries finite, the largest |entry| M of the linear part in [1e-80, 1e80] and its
    determinant (by cofactors, in floats) at least 1e-9 M^3, the linear part is far from singular: the
    cofactor sum's rounding error is below 30 eps M^3, so the true determinant is about as large; the
    largest singular value is at most 3 M, so the condition number is at most (3 M)^3 / det, about 3e10,
    well below MAX_CONDITION; and at those magnitudes no LU pivot or product is 0, overflows or underflows.
    np.linalg.det and np.linalg.cond would then give a finite non-zero determinant and a condition number
    under MAX_CONDITION, so the answer is the same without their cost (a third of the parse time of a scene
    of 10,000 shapes).  When this says no, is_singular asks NumPy as before."""
    rows = matrix.tolist()
    return math.isfinite(sum(rows[3])) and _affine_clearly_invertible(rows[0] + rows[1] + rows[2])


def _affine_clearly_invertible(affine: transforms.Affine) -> bool:
    """_clearly_invertible for the top three rows of a matrix, row after row (see transforms.Affine)."""
    # The sum is finite only if every entry is (one that overflows just leaves the question to NumPy).
    if not math.isfinite(sum(affine)):
        return False
    a, b, c, _, d, e, f, _, g, h, i, _ = affine
    size = max(abs(a), abs(b), abs(c), abs(d), abs(e), abs(f), abs(g), abs(h), abs(i))
    if not 1e-80 <= size <= 1e80:
        return False
    det = a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g)
    return abs(det) >= 1e-9 * size * size * size


def is_singular(matrix: np.ndarray) -> bool:
    """True if the transform has no usable inverse (hit tests need M⁻¹)."""
    if isinstance(matrix, np.ndarray) and matrix.shape == (4, 4) and _clearly_invertible(matrix):
        return False
    return _numpy_is_singular(matrix)


def _affine_is_singular(affine: transforms.Affine) -> bool:
    """is_singular for the matrix of an affine map given as transforms.Affine."""
    return not _affine_clearly_invertible(affine) and _numpy_is_singular(transforms.affine_matrix(affine))


def _numpy_is_singular(matrix: np.ndarray) -> bool:
    """The definition: a non-finite entry, a zero or non-finite determinant, or a condition number of the
    linear part above MAX_CONDITION."""
    linear = matrix[:3, :3]
    if not np.all(np.isfinite(matrix)):
        return True
    det = np.linalg.det(linear)
    if det == 0.0 or not np.isfinite(det):
        return True
    return not np.linalg.cond(linear) <= MAX_CONDITION


# ---------------------------------------------------------------------------------------------------------
# Public entry points.

def parse_sdl(text: str, base_dir: Optional[PathLike] = None, file: Optional[str] = None,
              strict: bool = True, fast: Optional[bool] = None) -> Scene:
    """Read SDL ``text``.

    ``base_dir`` is where ``mesh`` and ``makePixmap`` file names are looked up (the current folder if None);
    ``file`` names the text in messages.  With ``strict`` False, problems in the text never raise: each
    becomes one message in ``scene.warnings`` and reading goes on.

    A text of :data:`FAST_MIN_CHARS` characters or more is first offered to the C core's reader (tracer.sdl.fastread),
    which gives the same scene or declines, and then this reader reads it; ``fast`` True offers any text to
    it, False none (for tests).
    """
    if fast is None:
        fast = len(text) >= FAST_MIN_CHARS
    # Huge scales may overflow a transform to inf: the shape under it is reported as an error; NumPy's
    # overflow warning on the way would only repeat that.
    with collector_paused(), np.errstate(over="ignore", invalid="ignore"):
        if fast:
            from . import fastread  # deferred: the C reader's glue is loaded by the first text big enough for it
            scene = fastread.read(text, file)
            if scene is not None:
                return scene
        return _Reader(text, base_dir, file, strict).read()


def load(path: PathLike, strict: bool = True, fast: Optional[bool] = None) -> Scene:
    """Read an SDL file; names in it are relative to its folder.  A file that cannot be read raises SDLError."""
    path = Path(path)
    try:
        # utf-8-sig drops a byte-order mark; a stray byte in a comment must not stop the read.
        text = read_text(path, "scene file")
    except OSError as exc:
        raise SDLError(f"cannot read scene file: {exc.strerror or exc}", file=str(path)) from exc
    scene = parse_sdl(text, base_dir=path.parent, file=str(path), strict=strict, fast=fast)
    scene.source = path
    return scene
