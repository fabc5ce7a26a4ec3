"""Shared fixtures: the GL context (skipped locally without one, required on CI), paths, and
each statistical test's false-alarm rate (``false_alarms.py``)."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(Path(__file__).resolve().parent))  # tests import toys.py


@pytest.fixture(scope="session", autouse=True)
def sigint_delivered():
    """Tests that interrupt a run (in this process or in a `sppl sample` it starts) need
    SIGINT to reach it; a test session started in the background (`nohup`, `&`) inherits it
    ignored, and so would every process it starts, so the session takes Python's handler."""
    import signal

    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)
        yield
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    else:
        yield


@pytest.fixture(scope="session")
def require_gl():
    from sppl.errors import RenderError
    from sppl.render import gl_context

    try:
        gl_context()
    except RenderError as error:
        if os.environ.get("CI") == "true":
            pytest.fail(f"CI must be able to render: {error}")
        pytest.skip(f"no headless OpenGL context on this machine: {error}")


@pytest.fixture
def registered():
    """``register_likelihood`` for one test: the registry is as it was once the test ends,
    so a likelihood a test makes up is never seen by another."""
    from sppl.model import likelihoods

    saved = dict(likelihoods._registry)
    yield likelihoods.register_likelihood
    likelihoods._registry.clear()
    likelihoods._registry.update(saved)


@pytest.fixture(scope="session")
def root() -> Path:
    return ROOT


def pytest_configure(config):
    config.addinivalue_line(
        "markers", "false_alarm(rate): a statistical test's false-alarm rate, its share of the "
        "suite's budget (tests/false_alarms.py)")


@pytest.fixture
def false_alarm(request) -> float:
    """The rate the test's ``false_alarm`` marker gives it, to decide its verdict with."""
    marker = request.node.get_closest_marker("false_alarm")
    if marker is None:
        pytest.fail("a test that asks for its false-alarm rate needs @pytest.mark.false_alarm")
    return float(marker.args[0])


def pytest_collection_modifyitems(config, items):
    """With SPPL_FALSE_ALARMS=path, write every collected test's rate (None if it states none)
    and whether it is slow there: ``test_false_alarms.py`` reads the whole suite's so."""
    out = os.environ.get("SPPL_FALSE_ALARMS")
    if not out:
        return
    import json

    rows = []
    for item in items:
        marker = item.get_closest_marker("false_alarm")
        rows.append({"id": item.nodeid, "name": getattr(item, "originalname", item.name),
                     "rate": float(marker.args[0]) if marker else None,
                     "slow": item.get_closest_marker("slow") is not None})
    Path(out).write_text(json.dumps(rows))
