"""Golden files of the language (as stanc3's test/integration/{good,bad}).

``tests/golden/good/NAME.scn`` compiles and formats to ``NAME.fmt.scn``; ``tests/golden/bad/
NAME.scn`` fails with exactly the text in ``NAME.err``. After a deliberate change to a message
or to the canonical form, run ``python tests/golden/regenerate.py`` and review the diff.
"""

from __future__ import annotations

import ast
import dataclasses
import importlib.util
import re
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


# ---- every message the compiler can give has a bad case ----------------------------------

# Messages that no bad file can show when it is compiled, and why; each is tested elsewhere.
NOT_GOLDEN = {
    "the geometry of class": "raised once an object's values are known (test_language_features)",
    "the prior `": "a dependent prior, raised once an object's values are known "
                   "(test_language_features)",
    "its weights must not be negative nor all zero": "dependent categorical weights, raised "
                                                     "once an object's values are known "
                                                     "(test_language_features)",
    "cannot read the model file": "a file that cannot be read cannot be checked in "
                                  "(test_errors, test_language)",
    "this geometry cannot be evaluated": "a static element's constant parts are checked one by "
                                         "one before they are put together: a guard only",
    "syntax error": "lark's LALR parser raises only the unexpected token and character errors "
                    "that have their own messages: a guard only",
}
# The calls that report a message, and the other places a message is written down first.
_REPORTERS = {"error", "report", "ModelError", "_BadArguments"}


def _pattern(node) -> str | None:
    """A regular expression for the text a message expression makes (formatted values as
    wildcards), or None if it is not written out there (a variable)."""
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        return re.escape(node.value)
    if isinstance(node, ast.JoinedStr):
        return "".join(re.escape(v.value) if isinstance(v, ast.Constant) else ".*?"
                       for v in node.values)
    if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Add):
        left, right = _pattern(node.left), _pattern(node.right)
        return None if left is None or right is None else left + right
    if isinstance(node, ast.Call):  # ", ".join(...) and the like
        return ".*?"
    return None


def compiler_messages() -> list[tuple[str, int, str]]:
    """(file, line, pattern) of every message sppl/lang writes out: the first argument of
    each reporting call, a ``message = ...`` made before it is reported, and the (argument,
    message) pairs that ``_problems`` collects. ``arity_error`` builds its own."""
    import ast

    found = []
    for path in sorted((ROOT / "sppl" / "lang").glob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            candidates = []
            if isinstance(node, ast.Call) and node.args:
                func = node.func
                name = func.attr if isinstance(func, ast.Attribute) else getattr(func, "id", None)
                if name in _REPORTERS:
                    candidates.append(node.args[0])
                elif name == "append" and isinstance(node.args[0], ast.Tuple):
                    candidates.append(node.args[0].elts[-1])
            elif isinstance(node, ast.Assign) and any(
                isinstance(t, ast.Name) and t.id == "message" for t in node.targets
            ):
                candidates.append(node.value)
            for candidate in candidates:
                pattern = _pattern(candidate)
                if pattern is not None and pattern != ".*?":
                    found.append((path.name, node.lineno, pattern))
    return found


def _text(pattern: str) -> str:
    """A pattern's literal text (wildcards left as they are)."""
    return re.sub(r"\\(.)", r"\1", pattern)


def test_every_message_of_the_compiler_has_a_bad_case():
    messages = compiler_messages()
    assert len(messages) > 100  # the scan finds them
    shown = "".join(p.with_suffix(".err").read_text(encoding="utf-8") for p in BAD)
    shown += "wrong number of arguments"  # arity_error's own message: tests/golden/bad/arity_*
    missing = [
        f"sppl/lang/{file}:{line}: {_text(pattern)}"
        for file, line, pattern in messages
        if not re.search(pattern, shown)
        and not any(_text(pattern).startswith(start) for start in NOT_GOLDEN)
    ]
    assert not missing, (
        "messages that no tests/golden/bad case shows (add a case and run "
        "python tests/golden/regenerate.py):\n" + "\n".join(missing))
    # Each exception still names a message the compiler has.
    for start in NOT_GOLDEN:
        assert any(_text(p).startswith(start) for _, _, p in messages), start
