"""Golden files of the language (as stanc3's test/integration/{good,bad}).

``tests/golden/good/NAME.scn`` compiles and formats to ``NAME.fmt.scn``; ``tests/golden/bad/
NAME.scn`` fails with exactly the text in ``NAME.err``. After a deliberate change to a message
or to the canonical form, run ``python tests/golden/regenerate.py`` and review the diff.
"""

from __future__ import annotations

import dataclasses
import importlib.util
from pathlib import Path

import pytest

from sppl.errors import ModelError
from sppl.lang import load_model, parse
from sppl.lang.pretty import format_source

ROOT = Path(__file__).resolve().parent.parent
_spec = importlib.util.spec_from_file_location("regenerate", ROOT / "tests/golden/regenerate.py")
regenerate = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(regenerate)

GOOD = regenerate.cases("good")
BAD = regenerate.cases("bad")


@pytest.fixture(autouse=True)
def at_the_root(monkeypatch):
    monkeypatch.chdir(ROOT)  # messages name files relative to the repository root


def without_positions(node):
    """An AST as nested tuples, without spans, so that two spellings of a model compare."""
    if dataclasses.is_dataclass(node):
        fields = [
            (f.name, without_positions(getattr(node, f.name)))
            for f in dataclasses.fields(node)
            if f.name not in ("span", "path", "source", "comments")
        ]
        return (type(node).__name__, tuple(fields))
    if isinstance(node, tuple):
        return tuple(without_positions(n) for n in node)
    return "colour" if node == "color" else node


@pytest.mark.parametrize("path", GOOD, ids=lambda p: p.stem)
def test_good_model_compiles_and_formats_to_its_canonical_form(path):
    assert load_model(path).classes
    canonical = path.with_suffix(".fmt.scn").read_text(encoding="utf-8")
    assert format_source(path.read_text(encoding="utf-8"), str(path)) == canonical
    # Canonical text is a fixed point, and means what the original meant.
    assert format_source(canonical) == canonical
    assert without_positions(parse(canonical)) == without_positions(parse(path.read_text()))
    assert load_model(path.with_suffix(".fmt.scn")).class_names == load_model(path).class_names


@pytest.mark.parametrize("path", BAD, ids=lambda p: p.stem)
def test_bad_model_reports_exactly_its_expected_errors(path):
    with pytest.raises(ModelError) as info:
        load_model(path)
    assert str(info.value) + "\n" == path.with_suffix(".err").read_text(encoding="utf-8")


def test_there_are_enough_cases_and_each_has_its_expected_file():
    assert len(BAD) >= 30 and len(GOOD) >= 5
    for path in GOOD:
        assert path.with_suffix(".fmt.scn").exists(), path
    for path in BAD:
        assert path.with_suffix(".err").exists(), path
    expected = {p.stem for p in (ROOT / "tests/golden/bad").glob("*.err")}
    assert expected == {p.stem for p in BAD}, "an .err file without its .scn"
