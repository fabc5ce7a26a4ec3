"""The shortcuts of the per-object bookkeeping against their plain versions: every camera's
rectangle found at once (``DrawCache``) against one camera at a time (``CameraBounds``), the
inside test with its box pre-check against a solve for every part, and the no-overlap check
with its bounding-box pre-check against shapely on every pair."""

from __future__ import annotations

import numpy as np
import pytest
import shapely

from sppl.data.camera import Camera, look_at
from sppl.lang import load_model
from sppl.model.geometry import PRIMITIVES, Part, footprints_overlap, rotation, scaling, translation
from sppl.model.simulate import sample_objects
from sppl.model.trace import make_object, overlaps_any
from sppl.render.bounds import INSIDE_MARGIN, CameraBounds, contains, unit_corners, world_corners
from sppl.render.drawlist import DrawCache


def _part(rng, spread=1.5) -> Part:
    axis = rng.normal(size=3)
    matrix = (translation(*rng.uniform(-spread, spread, 2), rng.uniform(-0.3, 0.5))
              @ rotation(axis / np.linalg.norm(axis), rng.uniform(0, 2 * np.pi))
              @ scaling(*rng.uniform(0.05, 1.2, 3)))
    return Part(PRIMITIVES[rng.integers(len(PRIMITIVES))], matrix, (1.0, 0.0, 0.0))


def _camera(rng, eye) -> Camera:
    w, h = int(rng.integers(16, 80)), int(rng.integers(16, 80))
    target = rng.uniform(-1.0, 1.0, 3) if rng.random() < 0.8 else -np.asarray(eye)
    return Camera("c", w, h, rng.uniform(20, 60), rng.uniform(20, 60), w / 2, h / 2,
                  look_at(eye, target), depth_max=10.0)


def _cameras(rng, parts):
    """Cameras far away, near the scene, and some inside a part or behind another."""
    eyes = [rng.normal(size=3) * 4.0 + (0.0, 0.0, 2.0) for _ in range(4)]
    eyes += [rng.uniform(-1.5, 1.5, 3) for _ in range(2)]
    p = parts[0]
    eyes.append(p.matrix[:3] @ unit_corners(p.primitive).mean(axis=1))  # its box's centre
    return [_camera(rng, eye) for eye in eyes]


def _contains_by_solve(part: Part, point, margin=INSIDE_MARGIN) -> bool:
    """``contains`` without the box pre-check: the point in the part's own coordinates."""
    corners = unit_corners(part.primitive)
    lo, hi = corners[:3].min(axis=1), corners[:3].max(axis=1)
    try:
        local = np.linalg.solve(part.matrix, np.append(point, 1.0))[:3]
    except np.linalg.LinAlgError:
        return False
    pad = margin / np.maximum(np.linalg.norm(part.matrix[:3, :3], axis=0), 1e-12)
    return bool(np.all(local >= lo - pad) and np.all(local <= hi + pad))


@pytest.mark.parametrize("seed", range(6))
def test_every_camera_at_once_is_each_camera_alone(seed):
    rng = np.random.default_rng(seed)
    for _ in range(20):
        parts = [_part(rng) for _ in range(int(rng.integers(1, 4)))]
        bounds = [CameraBounds(c) for c in _cameras(rng, parts)]
        cache = DrawCache(bounds)
        drawn = cache.of_parts(parts)
        corners = world_corners(parts)
        assert drawn.rects == tuple(b.rect_of(corners) for b in bounds)
        assert drawn.inside == tuple(any(_contains_by_solve(p, b.position) for p in parts)
                                     for b in bounds)


def test_the_cases_the_rectangles_must_tell_apart():
    """In view, out of view, and reaching behind the camera (the whole image)."""
    camera = Camera("c", 32, 24, 30.0, 30.0, 16.0, 12.0, look_at((0, -5, 1), (0, 0, 0.5)), 10.0)
    cache = DrawCache([CameraBounds(camera)])
    ahead = Part("box", translation(0, 0, 0) @ scaling(0.5, 0.5, 0.5), (1, 0, 0))
    aside = Part("box", translation(8, 0, 0) @ scaling(0.5, 0.5, 0.5), (1, 0, 0))
    around = Part("box", translation(0, -5, 0) @ scaling(3, 3, 3), (1, 0, 0))
    (rect,) = cache.of_parts([ahead]).rects
    assert rect is not None and rect != (0, 24, 0, 32)
    assert cache.of_parts([aside]).rects == (None,)
    assert cache.of_parts([around]).rects == ((0, 24, 0, 32),)
    assert cache.of_parts([around]).inside == (True,)
    assert cache.of_parts([ahead, aside]).inside == (False,)


def test_a_corner_in_the_camera_plane_takes_the_whole_image():
    """A box whose face lies in the camera's plane has corners at depth exactly 0: they
    reach behind the near plane, so the rectangle is the whole image (and no division by
    that depth is made)."""
    camera = Camera("c", 32, 24, 30.0, 30.0, 16.0, 12.0, look_at((0, -5, 1), (0, 0, 1)), 10.0)
    part = Part("box", translation(0, -4.5, 1) @ scaling(1, 1, 1), (1, 0, 0))
    assert CameraBounds(camera).rect_of(world_corners([part])) == (0, 24, 0, 32)
    assert DrawCache([CameraBounds(camera)]).of_parts([part]).rects == ((0, 24, 0, 32),)


def test_the_depth_pre_check_never_hides_an_inside_camera():
    """Cameras within a few margins of a sheared part's box, most looking at it: the inside
    test's shortcut (no corner nearer than 3 margins) says outside only where the solve
    does. A shortcut at 1 margin instead of 3 fails here."""
    rng = np.random.default_rng(12)
    seen = set()
    for _ in range(300):
        part = _part(rng, spread=0.2)
        shear = np.eye(4)
        shear[0, 1], shear[1, 2] = rng.normal(size=2) * 0.5
        part = Part(part.primitive, part.matrix @ shear, part.colour)
        corners = part.matrix[:3] @ unit_corners(part.primitive)
        centre = corners.mean(axis=1)
        # A corner (where the widened box reaches furthest out) or a point of an edge, pushed
        # out along the direction from the centre.
        ends = rng.choice(8, size=2, replace=False)
        point = corners[:, ends] @ ((1.0, 0.0) if rng.random() < 0.5 else rng.dirichlet((1, 1)))
        away = (point - centre) / max(np.linalg.norm(point - centre), 1e-9)
        for offset in rng.uniform(0.0, 4.0 * INSIDE_MARGIN, 3):
            eye = point + offset * away
            target = centre if rng.random() < 0.8 else eye + rng.normal(size=3)
            camera = Camera("c", 32, 24, 30.0, 30.0, 16.0, 12.0, look_at(eye, target),
                            depth_max=10.0)
            (inside,) = DrawCache([CameraBounds(camera)]).of_parts([part]).inside
            assert inside == _contains_by_solve(part, eye)
            seen.add(inside)
    assert seen == {True, False}


def test_the_box_pre_check_never_hides_an_inside_camera():
    """Points near sheared, thin and tilted parts: the pre-check says outside only where the
    solve does."""
    rng = np.random.default_rng(11)
    for _ in range(300):
        part = _part(rng, spread=0.2)
        shear = np.eye(4)
        shear[0, 1], shear[1, 2] = rng.normal(size=2)
        part = Part(part.primitive, part.matrix @ shear, part.colour)
        centre = part.matrix[:3] @ unit_corners(part.primitive).mean(axis=1)
        for _ in range(10):
            point = centre + rng.normal(size=3) * rng.uniform(0.1, 2.0)
            assert contains(part, point) == _contains_by_solve(part, point)


@pytest.mark.parametrize("model_name", ["shapes.scn", "blocks.scn", "tabletop.scn"])
def test_the_overlap_pre_check_gives_the_plain_answer(root, model_name):
    model = load_model(root / "models" / model_name)
    if not model.no_overlap:
        pytest.skip("no constraint")
    rng = np.random.default_rng(3)
    checked = overlapping = 0
    while checked < 400:
        objects = [o for o in sample_objects(model, rng) if o.constrained]
        # Crowd them: positions drawn near the origin, so that many footprints meet.
        for o in objects[1:]:
            cls = o.cls
            values = dict(o.values)
            if cls.position:
                for name in cls.position:
                    values[name] = float(rng.uniform(-0.6, 0.6))
            moved = make_object(model, cls, values)
            if not moved.constrained:
                continue
            plain = any(footprints_overlap(moved.footprint, other.footprint)
                        for other in objects if other is not o)
            others = [other for other in objects if other is not o]
            assert overlaps_any(moved, others) == plain
            assert shapely.box(*moved.extent).contains(moved.footprint)
            checked += 1
            overlapping += plain
    assert 0 < overlapping < checked  # both answers were exercised
