"""The process-wide headless OpenGL context: the one place sppl creates one.

One context per process, because several moderngl contexts in one process have crashed on depth
reads (moderngl #745). It is a standalone EGL context so that no display is needed; on a machine
without a GPU, Mesa's llvmpipe provides it.
"""

from __future__ import annotations

import logging
import threading

import moderngl

from ..errors import RenderError

log = logging.getLogger(__name__)

GL_VERSION = 330
DEBIAN_PACKAGES = "libegl1 libgl1 libegl-mesa0 libgl1-mesa-dri"

_context: moderngl.Context | None = None
_lock = threading.Lock()


def gl_context() -> moderngl.Context:
    """The process's standalone EGL context, created on first use."""
    global _context
    with _lock:
        if _context is None:
            _context = _create()
        return _context


def renderer_string() -> str:
    """What draws the pixels, e.g. ``llvmpipe (LLVM 15.0.6, 256 bits)`` or an NVIDIA GPU."""
    return gl_context().info["GL_RENDERER"]


def _create() -> moderngl.Context:
    try:
        ctx = moderngl.create_context(standalone=True, backend="egl", require=GL_VERSION)
    except Exception as error:  # glcontext raises bare Exceptions whose text is the only clue
        reason = " ".join(str(error).split()) or type(error).__name__
        raise RenderError(
            f"could not create a headless OpenGL {GL_VERSION // 100}.{GL_VERSION // 10 % 10} "
            f"context through EGL ({reason}); on Debian or Ubuntu install the packages it "
            f"needs with `apt-get install {DEBIAN_PACKAGES}`"
        ) from error
    # Standalone contexts default to gc_mode None, which leaks every GL object not released
    # by hand; "auto" frees them when their Python wrappers are collected.
    ctx.gc_mode = "auto"
    # libglvnd may pick a GPU or Mesa's software device depending on the machine, and the
    # difference is a hundredfold in speed, so always say which one this process got.
    log.info("OpenGL renderer: %s (%s)", ctx.info["GL_RENDERER"], ctx.info["GL_VERSION"])
    return ctx
