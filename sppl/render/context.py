"""The process-wide headless OpenGL context: the one place sppl creates one.

One context per process, because several moderngl contexts in one process have crashed on depth
reads (moderngl #745). It is a standalone EGL context so that no display is needed; on a machine
without a GPU, Mesa's llvmpipe provides it.
"""

from __future__ import annotations

import logging
import os
import threading

import moderngl

from ..errors import RenderError

log = logging.getLogger(__name__)

GL_VERSION = 330
DEBIAN_PACKAGES = "libegl1 libgl1 libegl-mesa0 libgl1-mesa-dri"

# llvmpipe's rasteriser threads (LP_NUM_THREADS, default one per core) pay a hand-off and a
# wait on every flush, and sppl flushes once per camera pass for frames of a few thousand
# pixels: rasterising on the calling thread (0) measured 1.7x faster for a whole hypothesis
# and 1.8x for a single-object move (128x128, 2 cameras, K=3), and --chains runs one process
# per chain, which keeps every core busy anyway. A value in the environment wins.
LLVMPIPE_THREADS = "0"

_context: moderngl.Context | None = None
_lock = threading.Lock()
_state_owner: object | None = None


def gl_context() -> moderngl.Context:
    """The process's standalone EGL context, created on first use."""
    global _context
    with _lock:
        if _context is None:
            _context = _create()
        return _context


def claim_state(owner) -> bool:
    """Record that ``owner`` sets the shared context's state (capabilities, face winding,
    bound textures) from now on; True when another user has set it since ``owner`` last did,
    and ``owner`` must then set all it relies on. Every user of the context claims it before
    it draws, so that a user that draws many times in a row sets its state only once."""
    global _state_owner
    changed = _state_owner is not owner
    _state_owner = owner
    return changed


def renderer_string() -> str:
    """What draws the pixels, e.g. ``llvmpipe (LLVM 15.0.6, 256 bits)`` or an NVIDIA GPU."""
    return gl_context().info["GL_RENDERER"]


# What each failure of glcontext's EGL backend means, and the Debian package that fixes it.
# All four packages are needed (each was removed in turn to check): libEGL.so.1 and libGL.so.1
# are glvnd's dispatchers (libegl1, libgl1), which glcontext loads by name; EGL then needs a
# vendor library (libegl-mesa0, or a GPU driver's) to find any device, and Mesa's vendor needs
# its drivers, llvmpipe among them (libgl1-mesa-dri), to initialise one.
_LIKELY_MISSING = (
    ("libegl", "libegl1"),
    ("libgl", "libgl1"),
    ("found 0 devices", "libegl-mesa0, or the EGL library of the GPU's driver"),
    ("eglinitialize", "libgl1-mesa-dri"),
)


def _create() -> moderngl.Context:
    if not log.isEnabledFor(logging.DEBUG):
        # Mesa prints its own multi-line warnings when it fails; the error below says it all.
        os.environ.setdefault("EGL_LOG_LEVEL", "fatal")
    # Set only while the context is made (llvmpipe reads it then), so that processes this one
    # starts, which may not be sppl's, inherit the environment as the user left it.
    defaulted = "LP_NUM_THREADS" not in os.environ
    if defaulted:
        os.environ["LP_NUM_THREADS"] = LLVMPIPE_THREADS
    try:
        ctx = moderngl.create_context(standalone=True, backend="egl", require=GL_VERSION)
    except Exception as error:  # glcontext raises bare Exceptions whose text is the only clue
        reason = " ".join(str(error).split()) or type(error).__name__
        likely = next((pkg for clue, pkg in _LIKELY_MISSING if clue in reason.lower()), None)
        raise RenderError(
            f"could not create a headless OpenGL {GL_VERSION // 100}.{GL_VERSION // 10 % 10} "
            f"context through EGL ({reason}); on Debian or Ubuntu install the packages it "
            f"needs with `apt-get install {DEBIAN_PACKAGES}`"
            + (f" (the one missing here is likely {likely})" if likely else "")
        ) from error
    finally:
        if defaulted:
            del os.environ["LP_NUM_THREADS"]
    # Standalone contexts default to gc_mode None, which leaks every GL object not released
    # by hand; "auto" frees them when their Python wrappers are collected.
    ctx.gc_mode = "auto"
    # libglvnd may pick a GPU or Mesa's software device depending on the machine, and the
    # difference is a hundredfold in speed, so always say which one this process got.
    log.info("OpenGL renderer: %s (%s)", ctx.info["GL_RENDERER"], ctx.info["GL_VERSION"])
    return ctx
