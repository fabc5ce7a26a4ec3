"""The benchmark scripts run end to end and print their tables (the figures themselves are
recorded in benchmarks/README.md, never asserted: the machines that run tests are shared)."""

import subprocess
import sys

import pytest


def bench(root, script, *args):
    r = subprocess.run([sys.executable, str(root / "benchmarks" / script), *map(str, args)],
                       capture_output=True, text=True, timeout=600, check=False)
    assert r.returncode == 0, r.stderr
    return r.stdout


@pytest.mark.slow
def test_evaluations_prints_both_tables(root, require_gl):
    out = bench(root, "evaluations.py", "--quick", "--repeats", "1", "--seconds", "0.05")
    assert "| 3 | 2 | 128 |" in out
    for path in ("incremental (fast)", "full (fast)", "reference", "memory floor"):
        assert f"| {path} |" in out
    # Panda3D is optional: either its rows are there or the script says why not.
    assert "| panda3d |" in out or "panda3d path skipped" in out
    for row in ("| whole scene | mixture |", "| move | student_t |", "| noise move | mixture |"):
        assert row in out


@pytest.mark.slow
def test_versions_compares_two_checkouts(root, require_gl):
    out = bench(root, "versions.py", root, root, "--rounds", "1")
    assert "| whole hypothesis |" in out and "| single-object move |" in out
