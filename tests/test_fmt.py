"""``sppl fmt``: the canonical form of a model file, its fixed point, and the command."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from sppl.cli import main
from sppl.lang import parse
from sppl.lang.pretty import expression, format_source

ROOT = Path(__file__).resolve().parent.parent

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


# -- what the project ships is in canonical form ----------------------------------------------

SHIPPED = sorted(p for pattern in ("models/*.scn", "examples/**/*.scn")
                 for p in ROOT.glob(pattern))
DOC_PAGES = sorted([*ROOT.glob("docs/*.md"), ROOT / "README.md", *ROOT.glob("examples/**/*.md")])
FENCE = re.compile(r"^```([^\n]*)\n(.*?)^```\s*$", re.MULTILINE | re.DOTALL)


def doc_models() -> list[tuple[str, str]]:
    """Every ```scn block of the docs, named by page and line."""
    found = []
    for page in DOC_PAGES:
        text = page.read_text(encoding="utf-8")
        for m in FENCE.finditer(text):
            if m.group(1).split()[:1] == ["scn"]:
                line = text[: m.start()].count("\n") + 1
                found.append((f"{page.relative_to(ROOT)}:{line}", m.group(2)))
    return found


def test_every_shipped_model_is_in_canonical_form(capsys):
    assert len(SHIPPED) >= 5  # models/ and examples/: what a user starts from
    assert main(["fmt", "--check", *map(str, SHIPPED)]) == 0, capsys.readouterr().err


@pytest.mark.parametrize("where, text", doc_models(), ids=[w for w, _ in doc_models()])
def test_every_model_in_the_docs_is_in_canonical_form(where, text):
    """The tutorial's cylinders.scn among them: a reader who runs `sppl fmt --check` on what
    the docs show must not be told it is not canonical."""
    assert format_source(text, where) == text
