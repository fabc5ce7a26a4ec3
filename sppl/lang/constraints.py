"""Where objects may be: the constraints (no overlap, a bound on their number) and the region.

A part of the compiler (``sppl.lang.compile``), given the file's ``CompileContext``. A box or
polygon region restricts each placed class's position prior, once every class is compiled; a
camera region waits for the cameras (``sppl.model.region.bind``).
"""

from __future__ import annotations

from ..errors import Span
from . import ast
from .classes import whole
from .context import CompileContext
from .expressions import did_you_mean, known

_CONSTRAINTS = ("no_overlap", "max_objects")


class Constraints:
    """The constraints and region of one file."""

    def __init__(self, context: CompileContext) -> None:
        self.context = context
        self.expr = context.expr
        self.error = context.error
        self.no_overlap = False
        self.max_objects: int | None = None
        self.region = None  # sppl.model.region.Region or CamerasRegion
        self.region_span: Span | None = None
        self.restrictions: dict[str, object] = {}  # class: its restricted position prior

    def add_constraint(self, node: ast.Constraint) -> None:
        rule = node.rule
        ident = rule.func if isinstance(rule, ast.Call) else rule
        name = ident.text
        if name not in _CONSTRAINTS:
            self.error(
                f"unknown constraint `{name}`",
                ident.span,
                did_you_mean(name, _CONSTRAINTS) or known("constraints", _CONSTRAINTS),
            )
            return
        if not self.context.first(("constraint", name), ast.Setting(ident, ident, node.span)):
            return
        if name == "no_overlap":
            if isinstance(rule, ast.Call):
                self.error(
                    "`no_overlap` takes no arguments", rule.span, "write `constraint no_overlap`"
                )
                return
            self.no_overlap = True
            return
        if not isinstance(rule, ast.Call) or len(rule.args) != 1:
            self.error(
                "`max_objects` needs its bound: max_objects(n)",
                rule.span,
                "e.g. `constraint max_objects(10)`",
            )
            return
        arg = self.expr.positional(rule)
        if arg is not None:
            self.max_objects = whole(self.context, arg[0], "`max_objects`")

    def set_region(self, node: ast.Region) -> None:
        from ..model import region as regions

        kind = node.kind.text
        if self.region_span is not None:
            self.error(f"the region is already given on line {self.region_span.line}",
                       node.span, "a model has one region; merge them into one polygon")
            return
        self.region_span = node.span
        if kind not in regions.KINDS:
            self.error(f"unknown region `{kind}`", node.kind.span,
                       did_you_mean(kind, regions.KINDS) or known("regions", regions.KINDS))
            return
        scope = self.context.global_scope(where="a region")
        try:
            if kind == "cameras":
                names = []
                for a in node.args:
                    if isinstance(a, ast.String | ast.Name):
                        names.append(a.value if isinstance(a, ast.String) else a.id)
                    else:
                        self.error("`cameras(...)` takes the names of frames", a.span,
                                   'e.g. `region cameras(left, "right")`')
                        return
                self.region = regions.CamerasRegion(tuple(names), self._where(node.span))
            elif kind == "box":
                if len(node.args) != 4 or any(
                        isinstance(a, ast.Tuple | ast.String) for a in node.args):
                    self.error("`box` takes four numbers: box(x_min, y_min, x_max, y_max)",
                               node.span)
                    return
                values = self.expr.constants(node.args, scope)
                if values is not None:
                    self.region = regions.box(*values)
            else:
                points = []
                for a in node.args:
                    if not isinstance(a, ast.Tuple) or len(a.items) != 2:
                        self.error("a polygon's corners are (x, y) pairs", a.span,
                                   "e.g. `region polygon((0, 0), (4, 0), (0, 3))`")
                        return
                    xy = self.expr.constants(a.items, scope)
                    if xy is None:
                        return
                    points.append(xy)
                self.region = regions.polygon(points)
        except regions.RegionError as error:
            self.error(str(error), node.span)

    def _where(self, span: Span) -> str:
        return f"{self.context.program.path}:{span.line}:{span.column}"

    def restrict(self) -> None:
        """Each placed class's position prior restricted to a box or polygon region, with its
        normaliser (a camera region waits for the cameras: ``sppl.model.region.bind``)."""
        from ..model import region as regions

        if self.region is None or isinstance(self.region, regions.CamerasRegion):
            return
        for c in self.context.classes.values():
            if c.position is None:
                continue
            px, py = (c.parameter(n) for n in c.position)
            try:
                self.restrictions[c.name] = regions.restrict(
                    self.region, c.position, px.prior, py.prior, c.name)
            except regions.RegionError as error:
                self.error(str(error), self.region_span)
