"""docs/language.md is true: each of its ```scn examples parses and compiles, and its grammar is
the one in sppl/lang/scn.lark.

Every example is a complete model file. It is compiled as if it were a file in ``models/``,
so that the mesh and import paths in it name the shipped files (``meshes/mug.obj``,
``shapes.scn``), as the page says. An error is shown with the page's own line numbers.
"""

from __future__ import annotations

import importlib.util
import re
from dataclasses import dataclass
from pathlib import Path

import pytest

from sppl.errors import ModelError
from sppl.lang import compile_model, parse

ROOT = Path(__file__).resolve().parent.parent
DOC = ROOT / "docs" / "language.md"
# Where the examples are compiled from: the folder of the shipped models.
AS_IF_IN = ROOT / "models" / "language-md-example.scn"
# What a fenced block of the page may be; a block without a language would escape the test.
LANGUAGES = {"scn", "lark", "text", "toml", "sh"}

_spec = importlib.util.spec_from_file_location("update_grammar", ROOT / "docs/update_grammar.py")
update_grammar = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(update_grammar)


@dataclass(frozen=True)
class Block:
    language: str
    line: int  # of the first line inside the fence, 1-based
    text: str


def fenced_blocks(text: str) -> list[Block]:
    blocks, lines = [], text.splitlines()
    i = 0
    while i < len(lines):
        m = re.match(r"^```(\S*)\s*$", lines[i])
        if not m:
            i += 1
            continue
        start = i + 1
        end = next((j for j in range(start, len(lines)) if lines[j].strip() == "```"), None)
        if end is None:
            raise AssertionError(f"{DOC.name}:{i + 1}: a fence that is never closed")
        blocks.append(Block(m.group(1), start + 1, "\n".join(lines[start:end]) + "\n"))
        i = end + 1
    return blocks


BLOCKS = fenced_blocks(DOC.read_text(encoding="utf-8"))
EXAMPLES = [b for b in BLOCKS if b.language == "scn"]


def test_every_block_says_what_it_is():
    untagged = [f"line {b.line - 1}: ```{b.language}" for b in BLOCKS
                if b.language not in LANGUAGES]
    assert not untagged, (
        f"fenced blocks of {DOC.name} without a known language (an example of the language is "
        f"```scn, and is then compiled by this test): " + ", ".join(untagged))
    assert len(EXAMPLES) >= 12  # the page's examples are found


def _in_place(block: Block) -> str:
    """The example, pushed down to where it stands in the page, so that errors name its lines."""
    return "\n" * (block.line - 1) + block.text


def _shown(error: ModelError) -> str:
    return str(error).replace(str(AS_IF_IN), str(DOC.relative_to(ROOT)))


def _failure(block: Block) -> str | None:
    """Why the example does not parse or compile, or None."""
    text = _in_place(block)
    for what, step in (("parse", lambda: parse(text, str(AS_IF_IN))),
                       ("compile", lambda: compile_model(text, AS_IF_IN))):
        try:
            step()
        except ModelError as error:
            return f"the example at {DOC.name} line {block.line} does not {what}:\n{_shown(error)}"
    return None


@pytest.mark.parametrize("block", EXAMPLES, ids=lambda b: f"line{b.line}")
def test_the_example_parses_and_compiles(block):
    failure = _failure(block)
    if failure:
        pytest.fail(failure, pytrace=False)


def test_a_broken_example_is_reported_at_its_line_in_the_page():
    good = "class c {\n    count ~ poisson(1)\n    geometry sphere(1) colour rgb(1, 0, 0)\n}\n"
    assert _failure(Block("scn", 40, good)) is None
    failure = _failure(Block("scn", 40, good.replace("poisson(1)", "poisson(gama(2))")))
    assert failure.startswith("the example at language.md line 40 does not compile:\n"
                              "docs/language.md:41:21: unknown function `gama`"), failure
    failure = _failure(Block("scn", 40, good + "    ...\n"))
    assert "does not parse:\ndocs/language.md:44:5:" in failure, failure


def test_the_grammar_in_the_page_is_scn_lark():
    grammar = (ROOT / "sppl" / "lang" / "scn.lark").read_text(encoding="utf-8")
    [block] = [b for b in BLOCKS if b.language == "lark"]
    assert block.text == grammar, (
        "the grammar in docs/language.md differs from sppl/lang/scn.lark; "
        "run: python docs/update_grammar.py")
    doc = DOC.read_text(encoding="utf-8")
    assert update_grammar.with_grammar(doc, grammar) == doc


def test_the_grammar_script_replaces_only_the_grammar():
    doc = "# page\n\n```lark\nold: rule\n```\n\nafter\n"
    assert update_grammar.with_grammar(doc, "new: rule\n") == (
        "# page\n\n```lark\nnew: rule\n```\n\nafter\n")
    with pytest.raises(ValueError):
        update_grammar.with_grammar("no grammar here\n", "new: rule\n")
