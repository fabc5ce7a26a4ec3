"""Shared fixtures: the GL context (skipped locally without one, required on CI) and paths."""

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


@pytest.fixture(scope="session")
def root() -> Path:
    return ROOT
