"""How the command line hears SIGINT (Ctrl-C) and SIGTERM: within half a second, at every stage, and never
at the cost of the user's files.

A run goes through three phases, and one handler serves both signals in each:

* **starting** (from the first line of ``tracer/__init__.py`` to the command's start: NumPy, Pillow and the
  tracer being imported): nothing has been written yet, so the process ends at once, with status 128 + the
  signal (130 for SIGINT, 143 for SIGTERM) and an ``interrupted`` line.  Python's default would print a
  traceback for SIGINT, and SIGTERM would kill the process without a word.
* **working** (:func:`working`, around the command): the handler raises :class:`Interrupted` (a
  KeyboardInterrupt, so that everything on the way out runs its cleanup: a half-written file is removed) and
  main() returns 128 + the signal.  Inside :func:`shielded` (importing usd-core, whose module loader catches
  any exception, a KeyboardInterrupt too, and goes on with half its modules) the signal is only recorded,
  and raised when the block ends.
* **done** (the program's last output committed, see :func:`commit`, or its command over): a signal changes
  nothing any more, and the run ends as it would have.  A program whose command a signal ended ends at once
  (:func:`end_interrupted_program`), without Python's tidy way out.

Python runs signal handlers only between bytecodes of the main thread, so a signal that arrives while C
code runs (a ray tree, a BVH build, usd-core writing a file) waits for that code to return.  Once the C core
is loaded (it calls :func:`attach_library`), its handler stands in front of Python's while a command works
(tracer/native/interrupt.h): the tracer polls the signal at every ray, and a watchdog ends the process 0.3 s
after a signal that nothing acted on, first removing the named temporary files that :func:`holding`
registered.
"""
from __future__ import annotations

import contextlib
import os
import signal
import sys
from typing import Iterator, Optional

#: The signals heard: Ctrl-C and a polite request to stop.
SIGNALS = (signal.SIGINT, signal.SIGTERM)
#: How long the C watchdog waits for Python to act on a signal before it ends the process itself.
WATCHDOG_GRACE_MS = 300


class Interrupted(KeyboardInterrupt):
    """A SIGINT or SIGTERM heard while the command works; ``status`` is what the process exits with."""

    def __init__(self, signum: int):
        super().__init__(signal.Signals(signum).name)
        self.signum = signum

    @property
    def status(self) -> int:
        return 128 + self.signum


class _State:
    phase = "library"  # "starting", "working", "done"; "library": a program that only imports the tracer
    shield = 0
    pending: Optional[int] = None  # a signal heard inside a shield
    heard: Optional[int] = None
    final_output: Optional[str] = None  # the file whose commit finishes the program's work
    library = None  # the C core's library (attach_library), once loaded
    program = False  # this process is the command-line program (install_at_start was called)
    native_installed = False  # its handler stands in front of Python's


_state = _State()


def _handler(signum: int, frame) -> None:
    _state.heard = _state.heard or signum
    if _state.phase == "done":
        return
    if _state.phase == "starting":
        _say_interrupted()
        os._exit(128 + signum)
    if _state.shield:
        _state.pending = _state.pending or signum
        return
    raise Interrupted(signum)


def _say_interrupted() -> None:
    try:
        os.write(2, b"\ninterrupted\n")
    except OSError:
        pass


def install_at_start() -> None:
    """The starting phase's handler for both signals (by the program only, before its imports)."""
    _state.phase, _state.program = "starting", True
    for signum in SIGNALS:
        if signal.getsignal(signum) is not signal.SIG_IGN:  # (a shell's `cmd &` ignores SIGINT: keep that)
            signal.signal(signum, _handler)


def heard() -> Optional[int]:
    """The signal heard while the command worked, if any."""
    return _state.heard


def end_interrupted_program(status: int) -> None:
    """In the program, after a signal ended its command (the work given up, temporary files removed, the
    ``interrupted`` line said): end the process now, with ``status``.  Left to Python, the way out frees the
    scene object by object and tears usd-core down, which for a scene of 20,000 shapes took 0.5 to 0.8 s more
    (tests/test_signals.py), past the half second the user is promised.  A library caller gets the status back."""
    if not _state.program:
        return
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            stream.flush()
    os._exit(status)


@contextlib.contextmanager
def working(final_output: Optional[str] = None) -> Iterator[None]:
    """The working phase, for the block (on the main thread; elsewhere nothing changes).  ``final_output``:
    the file whose commit ends the program's work (after it, signals change nothing).  Afterwards the
    handlers are what they were (a test that calls main() gets its own back) and the phase is done."""
    try:
        previous = {signum: signal.signal(signum, _handler) for signum in SIGNALS
                    if signal.getsignal(signum) is not signal.SIG_IGN}
    except ValueError:  # not the main thread (told this way, without loading the threading module)
        yield
        return
    outer = (_state.phase, _state.final_output)
    _state.phase, _state.final_output, _state.heard, _state.pending = "working", final_output, None, None
    _install_native()
    try:
        yield
    finally:
        _state.phase = "done"
        if _state.native_installed:
            _state.library.rt_interrupt_uninstall()
            _state.native_installed = False
        # The program's work is over: from here to its exit signals are ignored (SIG_IGN, which Python keeps
        # while it shuts down; a handler of its own it would reset to the default, which kills the process).
        program = outer[0] == "starting"
        for signum, handler in previous.items():
            signal.signal(signum, signal.SIG_IGN if program else handler)
        _state.phase, _state.final_output = ("done" if program else outer[0]), outer[1]


def attach_library(lib) -> None:
    """The C core's library, once loaded (tracer.native calls this): from then on, while a command works, its
    handler stands in front of Python's and its watchdog is armed (see the module's note)."""
    _state.library = lib
    if _state.phase == "working":
        _install_native()


def _install_native() -> None:
    lib = _state.library
    if lib is None or _state.native_installed:
        return
    lib.rt_interrupt_clear()
    _state.native_installed = lib.rt_interrupt_install(WATCHDOG_GRACE_MS) == 0


@contextlib.contextmanager
def shielded() -> Iterator[None]:
    """A block no signal interrupts: one heard meanwhile is raised when it ends (see the module's note)."""
    _state.shield += 1
    try:
        yield
    finally:
        _state.shield -= 1
        if not _state.shield and _state.pending is not None and _state.phase == "working":
            signum, _state.pending = _state.pending, None
            raise Interrupted(signum)


def _raise_if_heard() -> None:
    """Interrupted if a signal has been heard and not yet acted on: one waiting while signals are blocked
    (taken, so that it is not delivered again), one the C core recorded at delivery whose Python handler has
    not run yet (it runs here), or one held by a shield."""
    if hasattr(signal, "sigtimedwait") and signal.sigpending() & set(SIGNALS):
        taken = signal.sigtimedwait(SIGNALS, 0)
        if taken is not None:
            _state.heard = _state.heard or taken.si_signo
            raise Interrupted(taken.si_signo)
    lib = _state.library if _state.native_installed else None
    signum = _state.pending or (lib.rt_interrupt_heard() if lib is not None else 0)
    if signum:
        _state.pending = None
        _let_python_handle_signals()  # (raises Interrupted, if Python's handler has not run yet)
        raise Interrupted(signum)


def _let_python_handle_signals() -> None:
    """A Python-level call: the interpreter runs the handlers of signals it has been told of on entering one."""


@contextlib.contextmanager
def holding(path: str) -> Iterator[None]:
    """While the block runs, the C watchdog removes ``path`` (a named temporary file) if it has to end the
    process.  Without the C core, or off the main program, nothing is registered."""
    lib = _state.library if _state.native_installed and _state.phase == "working" else None
    slot = lib.rt_interrupt_hold_file(os.fsencode(path)) if lib is not None else -1
    try:
        yield
    finally:
        if slot >= 0:
            lib.rt_interrupt_release_file(slot)


def commit(target: str, replace) -> None:
    """Run ``replace()`` (which puts ``target`` in place: a rename) unless a signal has been heard, with
    SIGINT and SIGTERM blocked meanwhile, so that the file is either committed or not, never committed by a
    run that then reports it was interrupted.  When ``target`` is the program's final output, the phase is
    done from then on.  A signal heard before: :class:`Interrupted` (the caller removes its temporary)."""
    blocking = hasattr(signal, "pthread_sigmask") and _state.phase == "working"
    if blocking:
        blocked = signal.pthread_sigmask(signal.SIG_BLOCK, SIGNALS)
    try:
        if _state.phase == "working":
            _raise_if_heard()
        replace()
        final = _state.final_output
        if final is not None and os.path.abspath(os.fspath(target)) == os.path.abspath(final):
            _state.phase = "done"
            if _state.native_installed:
                _state.library.rt_interrupt_disarm()
    finally:
        if blocking:
            signal.pthread_sigmask(signal.SIG_SETMASK, blocked)
