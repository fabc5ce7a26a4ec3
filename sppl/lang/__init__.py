"""The scene language: ``.scn`` text to a checked, compiled ``Model``."""

from .compile import compile_model, load_model
from .parser import parse

__all__ = ["compile_model", "load_model", "parse"]
