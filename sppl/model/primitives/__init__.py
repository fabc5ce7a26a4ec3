"""The shapes a geometry line can name, one module each: ``box``, ``cylinder``, ``cone``,
``sphere`` (base shapes) and ``capsule`` (made of base shapes). ``registry`` says what a
shape declares; docs/walkthroughs/adding-a-primitive.md adds one."""

from importlib import import_module

from .registry import (
    MESH_PREFIX,
    ROUND_SECTIONS,
    Hits,
    Primitive,
    find_primitive,
    get_primitive,
    primitive_names,
    register_primitive,
    unregister_primitive,
)

# The built-in base shapes, in a fixed order (tests draw random parts from them).
PRIMITIVES = ("box", "cylinder", "cone", "sphere")

# Each built-in module registers its shape when imported, in this order, which is the order
# that error messages list the known shapes in.
for _name in (*PRIMITIVES, "capsule"):
    import_module(f"{__name__}.{_name}")

__all__ = ["MESH_PREFIX", "PRIMITIVES", "ROUND_SECTIONS", "Hits", "Primitive", "find_primitive",
           "get_primitive", "primitive_names", "register_primitive", "unregister_primitive"]
