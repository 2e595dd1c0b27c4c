"""sdrpeer.errors: long echoed input is cut in every error message (`clip`, `shown`)."""

from __future__ import annotations

import pytest

from sdrpeer.errors import ConfigError, SystemFileError, clip, shown

N = "N" * 200_224
CUT_N = f"'{'N' * 60}'... (200,224 characters)"


@pytest.mark.parametrize(
    ("message", "expected"),
    [
        ("field 'name': got 'abc'", "field 'name': got 'abc'"),
        (f"field 'name': got '{N}'", f"field 'name': got {CUT_N}"),
        (f'got "{N}" twice', f'got "{"N" * 60}"... (200,224 characters) twice'),
        (f"no such file {N} here", f"no such file {'N' * 60}... (200,224 characters) here"),
        ("the robot's lab " + "x " * 200 + "can't", "the robot's lab " + "x " * 200 + "can't"),
        (f"'{'a' * 200}'", f"'{'a' * 200}'"),  # 200 characters are shown whole
        (f"'{'a' * 201}'", f"'{'a' * 60}'... (201 characters)"),
    ],
    ids=["short", "quoted", "double quoted", "unquoted run", "apostrophes", "at limit", "over"],
)
def test_clip(message: str, expected: str) -> None:
    assert clip(message) == expected
    assert clip(expected) == expected  # cutting twice changes nothing


def test_shown() -> None:
    assert shown("abc") == "'abc'"
    assert shown(N) == CUT_N
    assert shown(list(range(100_000))) == f"{list(range(100_000))!r}"[:60] + (
        f"... ({len(repr(list(range(100_000)))):,} characters)"
    )


def test_every_error_message_is_clipped() -> None:
    assert str(ConfigError(f"robot r: field 'name': got '{N}'")) == (
        f"robot r: field 'name': got {CUT_N}"
    )
    error = SystemFileError.collect("s.yaml", [f"s.yaml:1: got '{N}'", f"s.yaml:2: got '{N}'"])
    assert error.problems == [f"s.yaml:1: got {CUT_N}", f"s.yaml:2: got {CUT_N}"]
    assert str(error) == "\n".join(["s.yaml: 2 problems", *error.problems])
