"""Rendering parts into RGB and depth images: the OpenGL renderer and its numpy reference."""

from .context import gl_context, renderer_string
from .raycast import raycast
from .renderer import Renderer

__all__ = ["Renderer", "gl_context", "raycast", "renderer_string"]
