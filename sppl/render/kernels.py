"""The compiled twins of the fast path's per-move Python, where they were built.

``_kernels.c`` computes an object's draw data (``DrawCache.of_parts``) and a patch's change
against its parent's terms (``PixelScorer.change``) as the Python beside them does, without
the interpreter's cost per float: together they were a third of a single-object move's time.
The extension is built when sppl is installed with a C compiler at hand; without one the
install still succeeds and the Python twins run (``compiled`` is then None). Setting
``SPPL_PURE_PYTHON=1`` uses the twins even where the extension was built, to compare the two.
"""

from __future__ import annotations

import os

compiled = None
if os.environ.get("SPPL_PURE_PYTHON", "") in ("", "0"):
    try:
        from . import _kernels as compiled
    except ImportError:
        pass


def describe() -> str:
    """Which of the two runs, for benchmarks and bug reports."""
    if compiled is not None:
        return "compiled kernels"
    if os.environ.get("SPPL_PURE_PYTHON", "") not in ("", "0"):
        return "Python twins (SPPL_PURE_PYTHON is set)"
    return "Python twins (the compiled kernels were not built)"
