"""The suite's false-alarm budget holds (``false_alarms.py``): the rates of the default tests
add up to at most 1%, those of the slow tests to at most 1%, and every test that computes a
p-value or decides a statistical report states its rate (or says why it has none)."""

from __future__ import annotations

import ast
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
from false_alarms import BUDGET, EACH, NOT_FALSE_ALARMS, SLOW_BUDGET, SLOW_EACH

TESTS = Path(__file__).resolve().parent
# What makes a test statistical: it computes a p-value, or runs a check that decides by them.
STATISTICAL = re.compile(
    r"\.pvalue\b|p_value|kstest|ks_2samp|chisquare|binomtest|two_proportions_p|"
    r"\bprior_recovery\(|\bgeweke\(|\bsbc\(|\bverify_model\(|\"verify\"")


@pytest.fixture(scope="module")
def collected(tmp_path_factory) -> list[dict]:
    """Every test of the suite, slow ones included, with its rate: collected in a separate
    pytest (a few seconds), so that the whole suite is counted whatever this run selects."""
    out = tmp_path_factory.mktemp("collect") / "rates.json"
    env = {**os.environ, "SPPL_FALSE_ALARMS": str(out)}
    done = subprocess.run(
        [sys.executable, "-m", "pytest", "--collect-only", "-q", "-m", "", "-n", "0",
         "-p", "no:cacheprovider", str(TESTS)],
        env=env, capture_output=True, text=True, cwd=TESTS.parent)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    return json.loads(out.read_text())


def test_the_rates_add_up_to_at_most_the_budgets(collected):
    default = [t for t in collected if t["rate"] is not None and not t["slow"]]
    slow = [t for t in collected if t["rate"] is not None and t["slow"]]
    total, slow_total = sum(t["rate"] for t in default), sum(t["rate"] for t in slow)
    print(f"default suite: {len(default)} statistical tests, {total:.4g} in all (budget "
          f"{BUDGET:g}); slow: {len(slow)}, {slow_total:.4g} (budget {SLOW_BUDGET:g})")
    assert len(default) >= 40 and len(slow) >= 10
    assert total <= BUDGET and slow_total <= SLOW_BUDGET
    for t in default:
        assert 0.0 < t["rate"] <= EACH, t
    for t in slow:
        assert 0.0 < t["rate"] <= SLOW_EACH, t


def _statistical_tests() -> dict[str, str]:
    """Each test function whose body computes a p-value or runs a statistical check, by name,
    with its file."""
    found = {}
    for path in sorted(TESTS.glob("test_*.py")):
        if path.name == Path(__file__).name:  # its own examples are not tests
            continue
        source = path.read_text()
        for node in ast.parse(source).body:
            if isinstance(node, ast.FunctionDef) and node.name.startswith("test_") \
                    and STATISTICAL.search(ast.get_source_segment(source, node)):
                found[node.name] = path.name
    return found


def test_every_statistical_test_states_its_rate(collected):
    rated = {t["name"] for t in collected if t["rate"] is not None}
    names = {t["name"] for t in collected}
    missing = [f"{file}::{name}" for name, file in _statistical_tests().items()
               if name not in rated and name not in NOT_FALSE_ALARMS]
    assert not missing, f"statistical tests with no false_alarm marker: {missing}"
    assert not set(NOT_FALSE_ALARMS) - names, "NOT_FALSE_ALARMS names tests that do not exist"
    assert not set(NOT_FALSE_ALARMS) & rated, "a test is both rated and exempt"


def test_an_unrated_statistical_test_is_found():
    """The search itself: a test computing a p-value without a marker is named."""
    source = "def test_new():\n    assert stats.kstest(xs, 'norm').pvalue > 0.01\n"
    node = ast.parse(source).body[0]
    assert STATISTICAL.search(ast.get_source_segment(source, node))
