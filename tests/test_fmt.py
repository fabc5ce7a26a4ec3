"""``sppl fmt``: the canonical form of a model file, its fixed point, and the command."""

from __future__ import annotations

import pytest

from sppl.cli import main
from sppl.lang.pretty import expression, format_source
from sppl.lang import parse

MESSY = """\
let a=.5*-(2^3)^2 # a comment
class c{count~poisson(1)
  r:positive~gamma(2,rate=3)   geometry sphere(r) color rgb(1,0,0)}
"""
CANONICAL = """\
let a = 0.5 * -(2^3)^2  # a comment

class c {
    count ~ poisson(1)
    r : positive ~ gamma(2, rate=3)
    geometry sphere(r) colour rgb(1, 0, 0)
}
"""


def test_format_and_its_fixed_point():
    assert format_source(MESSY) == CANONICAL
    assert format_source(CANONICAL) == CANONICAL


@pytest.mark.parametrize(
    "text",
    [
        "1 - (2 - 3)",
        "1 - 2 - 3",
        "a / (b * c)",
        "a * b / c",
        "-2^2",
        "(-2)^2",
        "2^3^2",
        "(2^3)^2",
        "2^-1",
        "-(a + b)",
        "(a + b) * (c - d)",
        "f(a, b=2, c: 3)",
    ],
)
def test_expressions_keep_their_meaning_with_the_fewest_parentheses(text):
    node = parse(f"let x = {text}").statements[0].value
    assert expression(node) == text


def test_the_command(tmp_path, capsys):
    messy = tmp_path / "messy.scn"
    messy.write_text(MESSY)
    assert main(["fmt", str(messy)]) == 0
    assert capsys.readouterr().out == CANONICAL
    assert main(["fmt", "--check", str(messy)]) == 1
    assert "not in canonical form" in capsys.readouterr().err
    assert main(["fmt", "--write", str(messy)]) == 0
    assert messy.read_text() == CANONICAL
    assert main(["fmt", "--check", str(messy)]) == 0


def test_a_syntax_error_is_reported_and_nothing_written(tmp_path, capsys):
    bad = tmp_path / "bad.scn"
    bad.write_text("let a = (1\n")
    assert main(["fmt", "--write", str(bad)]) == 1
    assert "bad.scn:1:11: the file ends too early; expected `)`" in capsys.readouterr().err
    assert bad.read_text() == "let a = (1\n"
