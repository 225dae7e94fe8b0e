
import math

import pytest
from hypothesis import given, settings, strategies as st

from tracer.sdl.lexer import Token, is_number, to_float, tokenize


def texts(source):
    return [t.text for t in tokenize(source)]


def test_white_space_separates_tokens():
    assert texts("  light 1\t2\r\n3  ") == ["light", "1", "2", "3"]


def test_braces_are_tokens_of_their_own():
    assert texts("def bar{sphere}") == ["def", "bar", "{", "sphere", "}"]
    assert texts("a}b{{c") == ["a", "}", "b", "{", "{", "c"]


def test_comment_runs_to_end_of_line_and_ends_the_token():
    # The book's lexer would glue these into 'spherecube'; the project keeps them apart.
    assert texts("sphere!x\ncube") == ["sphere", "cube"]
    assert texts("! whole line\nscale 1 2 3 ! trailing words { }\n!") == ["scale", "1", "2", "3"]


def test_positions_are_one_based_lines_and_columns():
    tokens = tokenize("light 1\n  \tcube {x}\n\n!c\n  pop")
    assert tokens == [Token("light", 1, 1), Token("1", 1, 7), Token("cube", 2, 4), Token("{", 2, 9),
                      Token("x", 2, 10), Token("}", 2, 11), Token("pop", 5, 3)]


def test_crlf_does_not_shift_columns_or_lines():
    assert tokenize("a b\r\nc\r\n") == [Token("a", 1, 1), Token("b", 1, 3), Token("c", 2, 1)]


def test_empty_and_comment_only_text():
    assert tokenize("") == []
    assert tokenize("! nothing here\n   \n") == []


def test_file_names_stay_one_token():
    assert texts("mesh ../meshes/pawn-2.3vn") == ["mesh", "../meshes/pawn-2.3vn"]


@pytest.mark.parametrize("text, value", [
    (".5", 0.5), ("-2", -2.0), ("1e3", 1000.0), ("+3.", 3.0), ("0", 0.0), ("-0.25E-2", -0.0025), ("7.", 7.0)])
def test_decimal_numbers(text, value):
    assert is_number(text)
    assert to_float(text) == value


@pytest.mark.parametrize("text", [
    "nan", "NaN", "inf", "-inf", "Infinity", "1e999", "1.2.3", "e5", "-", ".", "0x10", "1_000", "3f", "--1", "", "1e"])
def test_things_that_are_not_numbers(text):
    assert not is_number(text)
    assert to_float(text) is None


@given(st.lists(st.from_regex(r"[A-Za-z0-9.+\-]{1,8}", fullmatch=True), max_size=20))
def test_joining_words_with_any_separator_gives_them_back(words):
    assert texts(" ".join(words)) == words
    assert texts("\n".join(words)) == words
    assert texts(" ! comment\n".join(words)) == words


@given(st.floats(allow_nan=False, allow_infinity=False))
def test_repr_of_any_finite_float_is_a_number_with_the_same_value(x):
    assert to_float(repr(x)) == x


@given(st.text(max_size=40))
def test_tokens_never_contain_space_braces_or_comments(source):
    for token in tokenize(source):
        assert token.text
        assert token.text in "{}" or not any(c.isspace() or c in "{}!" for c in token.text)
        line = source.split("\n")[token.line - 1]
        assert line[token.column - 1:token.column - 1 + len(token.text)] == token.text



@pytest.mark.parametrize("text", [" 1", "1 ", "1\n", "\u0663", "\u0661.\u0662", "1_0"])
def test_what_float_takes_but_sdl_does_not(text):
    """Python's float() reads these (white space, other scripts' digits, underscores); SDL does not."""
    assert float(text) == float(text)
    assert to_float(text) is None


@settings(max_examples=400, deadline=None)
@given(st.one_of(st.text(alphabet="0123456789.eE+-_ x", max_size=8),
                 st.floats(allow_nan=True, allow_infinity=True).map(repr),
                 st.text(max_size=6)))
def test_to_float_takes_exactly_the_number_pattern(text):
    from tracer.sdl.lexer import NUMBER_RE
    expected = float(text) if NUMBER_RE.fullmatch(text) else None
    if expected is not None and not math.isfinite(expected):
        expected = None
    assert to_float(text) == expected


@settings(max_examples=300, deadline=None)
@given(st.lists(st.one_of(st.text(alphabet="0123456789.eE+-_ xn", min_size=1, max_size=6).filter(lambda w: not w.isspace()),
                          st.floats().map(repr)), max_size=6))
def test_several_words_at_once_are_what_each_is_alone(words):
    from tracer.sdl.lexer import to_floats
    words = [w for w in words if w.split() == [w]]  # tokens: no white space in them
    alone = tuple(map(to_float, words))
    assert to_floats(words) == (None if None in alone else alone)


@settings(max_examples=200, deadline=None)
@given(st.lists(st.sampled_from(["a", "b1", " ", "  ", "\t", "\r", "\n", "\n", "{", "}", "!", "! name: x", "é"]),
                max_size=40).map("".join))
def test_blocks_of_any_size_give_the_same_tokens_and_places(source):
    """The lexer splits a text a block of lines at a time; where the blocks end changes nothing."""
    from tracer.sdl import lexer
    names = []
    whole = tokenize(source, names)
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(lexer, "BLOCK_CHARS", 1)
        patch.setattr(lexer, "_FAR", 1)  # and every place from its line's token starts
        small_names = []
        assert tokenize(source, small_names) == whole
        assert small_names == names
