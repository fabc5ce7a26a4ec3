"""Where objects may be: a region of the ground that restricts the position priors.

``region box(x0, y0, x1, y1)``, ``region polygon((x, y), ...)`` or ``region cameras`` (the
ground the cameras' images cover) restricts every class that has a ground position (x, y) to
positions inside the region. Each such class's position prior becomes the *truncated* prior

    p_R(x, y) = p_x(x) p_y(y) 1[(x, y) in R] / Z,      Z = P_{p_x p_y}((x, y) in R),

and ``count ~ poisson(lambda)`` stays the number of objects of the class in the region: the
scene is the Poisson process of intensity lambda p_R, so every object's prior carries -log Z
(docs/inference.md: Z cancels in parameter moves, but not in births and deaths, whose ratio
weighs lambda p_R against the proposal's density).

Z is exact for a box (a product of two CDF differences). For a polygon (and the cameras'
footprints, a union of polygons) it is integrated numerically: Z = int p_x(x) S(x) dx, where
S(x) = sum over the intervals of the polygon's vertical section at x of F_y(hi) - F_y(lo), by
Gauss-Legendre quadrature on each slab between consecutive vertices (S is smooth there), the
number of nodes doubled until two estimates agree to ``TOLERANCE`` (relative); ``error`` holds
the last difference. Drawing from p_R draws from the prior truncated to the region's bounding
box by inverse CDFs and rejects points outside the region (the box's shape, not the prior,
sets the acceptance rate).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import shapely
from scipy import optimize, special

from ..errors import SpplError
from .distributions import Normal, TruncatedNormal, Uniform

KINDS = ("box", "polygon", "cameras")

# Relative agreement of two quadrature estimates of a polygon's Z.
TOLERANCE = 1e-10
MAX_NODES = 1280


class RegionError(SpplError):
    """A region that cannot restrict the priors: empty, degenerate, or naming no camera."""


# ---------------------------------------------------------------------------------------------
# Shapes


@dataclass(frozen=True, eq=False)
class Region:
    """A closed set of the ground plane: a box, or a union of polygons (shapely)."""

    kind: str  # "box", "polygon" or "cameras": what the model file said
    geometry: Any  # shapely Polygon or MultiPolygon
    is_box: bool = False
    description: str = ""

    def __post_init__(self) -> None:
        shapely.prepare(self.geometry)  # point tests against it run on every proposal

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        return tuple(float(v) for v in self.geometry.bounds)

    @property
    def area(self) -> float:
        return float(self.geometry.area)

    def contains(self, x: float, y: float) -> bool:
        if self.is_box:
            x0, y0, x1, y1 = self.bounds
            return x0 <= x <= x1 and y0 <= y <= y1
        return bool(shapely.intersects_xy(self.geometry, x, y))

    def sections(self, axis: int, at: np.ndarray) -> list[list[tuple[float, float]]]:
        """For each value in ``at`` of coordinate ``axis`` (0: x, 1: y), the intervals of the
        other coordinate inside the region (even-odd crossings of every ring's edges)."""
        at = np.atleast_1d(np.asarray(at, dtype=float))
        if self.is_box:
            x0, y0, x1, y1 = self.bounds
            (a0, a1), (b0, b1) = ((x0, x1), (y0, y1)) if axis == 0 else ((y0, y1), (x0, x1))
            return [[(b0, b1)] if a0 <= a <= a1 else [] for a in at]
        p, q = _edges(self.geometry)
        u0, u1 = p[:, axis], q[:, axis]
        v0, v1 = p[:, 1 - axis], q[:, 1 - axis]
        lo, hi = np.minimum(u0, u1), np.maximum(u0, u1)
        out = []
        for a in at:
            cross = (lo <= a) & (a < hi)  # half-open: a vertex is crossed once
            t = (a - u0[cross]) / (u1[cross] - u0[cross])
            v = np.sort(v0[cross] + t * (v1[cross] - v0[cross]))
            out.append([(float(v[i]), float(v[i + 1])) for i in range(0, len(v) - 1, 2)])
        return out


def _edges(geometry) -> tuple[np.ndarray, np.ndarray]:
    rings = []
    for poly in getattr(geometry, "geoms", [geometry]):
        rings.append(np.asarray(poly.exterior.coords))
        rings += [np.asarray(r.coords) for r in poly.interiors]
    p = np.concatenate([r[:-1] for r in rings])
    q = np.concatenate([r[1:] for r in rings])
    return p, q


def box(x0: float, y0: float, x1: float, y1: float) -> Region:
    if not (x0 < x1 and y0 < y1):
        raise RegionError(f"the box ({x0:g}, {y0:g}, {x1:g}, {y1:g}) is empty: write "
                          "box(x_min, y_min, x_max, y_max) with x_min < x_max and y_min < y_max")
    return Region("box", shapely.box(x0, y0, x1, y1), is_box=True,
                  description=f"box({x0:g}, {y0:g}, {x1:g}, {y1:g})")


def polygon(points: Sequence[tuple[float, float]]) -> Region:
    pts = [(float(x), float(y)) for x, y in points]
    if len(pts) < 3:
        raise RegionError(f"a polygon needs at least 3 corners, got {len(pts)}")
    shape = shapely.Polygon(pts)
    if shape.convex_hull.area <= 0.0:
        raise RegionError("the polygon is degenerate: its corners enclose no area")
    if not shape.is_valid:
        raise RegionError(f"the polygon's edges cross ({shapely.is_valid_reason(shape)}): "
                          "list its corners in order around it")
    text = ", ".join(f"({x:g}, {y:g})" for x, y in pts)
    return Region("polygon", shape, description=f"polygon({text})")


def camera_footprint(camera) -> Any:
    """The ground (z = 0) an image covers between the near plane and ``depth_max`` along the
    optical axis: a convex polygon (empty when the camera does not see the ground)."""
    a = camera.w2c[:3]  # camera coordinates of (x, y, 0): a[:, 0] x + a[:, 1] y + a[:, 3]
    cx_, cy_, cz = a[0], a[1], a[2]
    depth = -cz  # the z-depth, positive in front of the camera
    w, h = camera.width, camera.height
    # Each side of the frustum is a linear inequality g . (cam x, cam y, depth) >= 0.
    sides = [
        (0.0, 0.0, 1.0, -camera.near),
        (0.0, 0.0, -1.0, camera.depth_max),
        (camera.fx, 0.0, camera.cx, 0.0),  # u >= 0
        (-camera.fx, 0.0, w - camera.cx, 0.0),  # u <= w
        (0.0, -camera.fy, camera.cy, 0.0),  # v >= 0
        (0.0, camera.fy, h - camera.cy, 0.0),  # v <= h
    ]
    centre = camera.position[:2]
    r = 4.0 * (camera.depth_max + 1.0) * (1.0 + max(w / camera.fx, h / camera.fy))
    poly = [centre + (-r, -r), centre + (r, -r), centre + (r, r), centre + (-r, r)]
    for gx, gy, gd, g0 in sides:
        coef = gx * cx_ + gy * cy_ + gd * depth  # (x, y, _, 1) coefficients
        poly = _clip(poly, coef[0], coef[1], coef[3] + g0)
        if not poly:
            return shapely.Polygon()
    return shapely.Polygon(poly)


def _clip(poly, a: float, b: float, c: float):
    """Sutherland-Hodgman: the part of a convex polygon where a x + b y + c >= 0."""
    out = []
    n = len(poly)
    for i in range(n):
        p, q = np.asarray(poly[i]), np.asarray(poly[(i + 1) % n])
        fp, fq = a * p[0] + b * p[1] + c, a * q[0] + b * q[1] + c
        if fp >= 0:
            out.append(p)
        if (fp >= 0) != (fq >= 0):
            out.append(p + (q - p) * (fp / (fp - fq)))
    return out


def cameras_region(cameras: Sequence, names: Sequence[str] = ()) -> Region:
    """The union of the ground footprints of the named cameras (all when none is named)."""
    known = {c.name: c for c in cameras}
    for n in names:
        if n not in known:
            raise RegionError(
                f"region cameras: unknown camera '{n}'; the observations have "
                + (", ".join(f"'{k}'" for k in known) or "no cameras"))
    chosen = [known[n] for n in names] if names else list(cameras)
    if not chosen:
        raise RegionError("region cameras: there are no cameras to take the region from; "
                          "give observations (--obs) or write a box or polygon region")
    shape = shapely.union_all([camera_footprint(c) for c in chosen])
    if shape.is_empty or shape.area <= 0.0:
        raise RegionError("region cameras: no camera sees the ground (between its near plane "
                          "and depth_max), so the region is empty")
    shape = shapely.normalize(shape)
    what = ", ".join(c.name for c in chosen)
    return Region("cameras", shape, description=f"the ground seen by {what}")


# ---------------------------------------------------------------------------------------------
# A class's restricted position prior


def _interval_mass(dist, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    lo, hi = np.asarray(lo, dtype=float), np.asarray(hi, dtype=float)
    if isinstance(dist, Normal):  # differences on the side of the tail where they are exact
        a, b = (lo - dist.mu) / dist.sigma, (hi - dist.mu) / dist.sigma
        return np.where(a > 0, special.ndtr(-a) - special.ndtr(-b),
                        special.ndtr(b) - special.ndtr(a))
    return np.asarray(dist.cdf(hi), dtype=float) - np.asarray(dist.cdf(lo), dtype=float)


def _sample_interval(dist, lo: float, hi: float, rng: np.random.Generator) -> float:
    """A draw of ``dist`` restricted to [lo, hi], by its inverse CDF."""
    if isinstance(dist, Normal):
        return TruncatedNormal(dist.mu, dist.sigma, lo, hi).sample(rng)
    if isinstance(dist, Uniform):
        return float(rng.uniform(max(lo, dist.low), min(hi, dist.high)))
    s0, s1 = dist.support()
    lo, hi = max(lo, s0), min(hi, s1)
    f0, f1 = float(dist.cdf(lo)), float(dist.cdf(hi))
    u = f0 + rng.random() * (f1 - f0)
    if not (math.isfinite(lo) and math.isfinite(hi)):
        width = 1.0
        while float(dist.cdf(lo if math.isfinite(lo) else hi - width)) > u and not math.isfinite(lo):
            width *= 2.0
        lo = lo if math.isfinite(lo) else hi - width
        while not math.isfinite(hi) and float(dist.cdf(lo + width)) < u:
            width *= 2.0
        hi = hi if math.isfinite(hi) else lo + width
    return float(optimize.brentq(lambda x: float(dist.cdf(x)) - u, lo, hi, xtol=1e-13))


def _log_pdf(dist, x: np.ndarray) -> np.ndarray:
    return np.array([dist.log_prob(float(v)) for v in np.atleast_1d(x)])


@dataclass(frozen=True, eq=False)
class Restriction:
    """A class's position prior restricted to a region: p_x p_y 1_R / Z."""

    region: Region
    names: tuple[str, str]
    x_prior: Any
    y_prior: Any
    log_mass: float  # log Z
    error: float = 0.0  # an estimate of the absolute error of Z (0 where exact)
    _box: tuple[float, float, float, float] = field(default=(0.0, 0.0, 0.0, 0.0), repr=False)

    def contains(self, values: Mapping[str, Any]) -> bool:
        return self.region.contains(values[self.names[0]], values[self.names[1]])

    # -- densities -----------------------------------------------------------------------------

    def log_correction(self, values: Mapping[str, Any], only=None) -> float:
        """What the restriction adds to the log prior of ``values`` (of the parameters in
        ``only``, given the others, as ``ObjectClass.log_prior``): the indicator and -log Z
        for the joint density, or for one coordinate given the other its section's mass."""
        xn, yn = self.names
        has_x = only is None or xn in only
        has_y = only is None or yn in only
        if not (has_x or has_y):
            return 0.0
        x, y = values[xn], values[yn]
        if not self.region.contains(x, y):
            return -math.inf
        if has_x and has_y:
            return -self.log_mass
        axis, at, other = (0, x, self.y_prior) if has_y else (1, y, self.x_prior)
        mass = sum(float(_interval_mass(other, lo, hi))
                   for lo, hi in self.region.sections(axis, [at])[0])
        return -math.log(mass) if mass > 0 else -math.inf

    # -- draws ---------------------------------------------------------------------------------

    def sample(self, rng: np.random.Generator, values: dict[str, Any], given) -> None:
        """Set the position in ``values`` to a draw of the restricted prior, given what
        ``given`` fixes (nothing, one coordinate, or both)."""
        xn, yn = self.names
        gx, gy = xn in given, yn in given
        if gx and gy:
            return
        if gx or gy:
            axis, at, name, dist = (0, given[xn], yn, self.y_prior) if gx else (
                1, given[yn], xn, self.x_prior)
            pieces = self.region.sections(axis, [at])[0]
            masses = np.array([float(_interval_mass(dist, lo, hi)) for lo, hi in pieces])
            if not len(pieces) or masses.sum() <= 0.0:
                values[name] = dist.sample(rng)  # outside the region: the prior scores 0
                return
            k = int(rng.choice(len(pieces), p=masses / masses.sum()))
            values[name] = _sample_interval(dist, *pieces[k], rng)
            return
        x0, y0, x1, y1 = self._box
        while True:
            x = _sample_interval(self.x_prior, x0, x1, rng)
            y = _sample_interval(self.y_prior, y0, y1, rng)
            if self.region.contains(x, y):
                values[xn], values[yn] = x, y
                return


    def rejection_draws(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """The slow, obviously correct twin of ``sample``: ``n`` positions (n, 2) drawn from
        the unrestricted priors, keeping those inside the region."""
        kept = []
        while len(kept) < n:
            x, y = self.x_prior.sample(rng), self.y_prior.sample(rng)
            if self.region.contains(x, y):
                kept.append((x, y))
        return np.array(kept)

    def inside(self, tries: int, rng: np.random.Generator) -> int:
        """How many of ``tries`` draws from the unrestricted priors land inside the region:
        Binomial(tries, Z), the twin of ``log_mass``."""
        return sum(self.region.contains(self.x_prior.sample(rng), self.y_prior.sample(rng))
                   for _ in range(tries))


def restrict(region: Region, names: tuple[str, str], x_prior, y_prior,
             class_name: str = "") -> Restriction:
    """The restriction of a class's independent position priors to ``region``, with Z."""
    x0, y0, x1, y1 = region.bounds
    sx, sy = x_prior.support(), y_prior.support()
    bx = (max(x0, sx[0]), min(x1, sx[1]))
    by = (max(y0, sy[0]), min(y1, sy[1]))
    if region.is_box:
        z = float(_interval_mass(x_prior, *bx)) * float(_interval_mass(y_prior, *by)) if (
            bx[0] < bx[1] and by[0] < by[1]) else 0.0
        error = 0.0
    else:
        z, error = _polygon_mass(region, x_prior, y_prior, bx)
    if not z > 0.0:
        raise RegionError(
            f"the region {region.description} holds no prior mass of "
            f"{class_name + '.' if class_name else ''}{names[0]}, {names[1]} "
            f"({x_prior}, {y_prior}): no object could be placed; widen the region or the priors")
    return Restriction(region, names, x_prior, y_prior, math.log(z), error,
                       (bx[0], by[0], bx[1], by[1]))


def _polygon_mass(region: Region, x_prior, y_prior, bx) -> tuple[float, float]:
    p, q = _edges(region.geometry)
    breaks = np.unique(np.concatenate([p[:, 0], q[:, 0], [bx[0], bx[1]]]))
    breaks = breaks[(breaks >= bx[0]) & (breaks <= bx[1])]
    slabs = list(itertools.pairwise(breaks))

    def estimate(n: int) -> float:
        t, w = np.polynomial.legendre.leggauss(n)
        total = 0.0
        for a, b in slabs:
            xs = 0.5 * (b - a) * t + 0.5 * (a + b)
            secs = region.sections(0, xs)
            s = np.array([sum(float(_interval_mass(y_prior, lo, hi)) for lo, hi in sec)
                          for sec in secs])
            total += 0.5 * (b - a) * float(np.sum(w * np.exp(_log_pdf(x_prior, xs)) * s))
        return total

    n, z = 10, estimate(10)
    while True:
        n *= 2
        z2 = estimate(n)
        error = abs(z2 - z)
        if error <= TOLERANCE * max(z2, 1e-300) or n >= MAX_NODES:
            return z2, error
        z = z2


# ---------------------------------------------------------------------------------------------
# A region of the cameras, bound when the cameras are known


@dataclass(frozen=True)
class CamerasRegion:
    """``region cameras[(names)]`` before the observations' cameras are known."""

    names: tuple[str, ...] = ()
    where: str = ""  # file:line:column of the statement, for errors


def bind_region(model, cameras: Sequence | None):
    """``model`` with a ``region cameras`` resolved against ``cameras`` (its classes' position
    priors restricted to their footprints); any other model as it is."""
    spec = model.region
    if not isinstance(spec, CamerasRegion):
        return model
    import dataclasses

    try:
        region = cameras_region(list(cameras or ()), spec.names)
        classes = tuple(
            dataclasses.replace(c, restriction=restrict(
                region, c.position, c.parameter(c.position[0]).prior,
                c.parameter(c.position[1]).prior, c.name))
            if c.position else c
            for c in model.classes
        )
    except RegionError as error:
        raise RegionError(f"{spec.where}: {error}" if spec.where else str(error)) from None
    return dataclasses.replace(model, classes=classes, region=region)


def region_text(model) -> str:
    """What a model's region is, in a line (``sppl check``)."""
    spec = model.region
    if isinstance(spec, CamerasRegion):
        which = ", ".join(spec.names) if spec.names else "every camera"
        return f"the ground the cameras see ({which}), known once the observations are"
    masses = ", ".join(f"{c.name} {math.exp(c.restriction.log_mass):.4g}"
                       for c in model.classes if c.restriction is not None)
    return f"{spec.description}; prior mass inside: {masses}"
