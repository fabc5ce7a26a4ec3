"""Shared fixtures: the GL context (skipped locally without one, required on CI) and paths."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(Path(__file__).resolve().parent))  # tests import toys.py


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
