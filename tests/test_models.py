"""Every shipped model: it compiles, samples from its prior, renders, and its derived sampler
recovers its prior (the check ``sppl verify`` runs, kept short here)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from sppl import moves
from sppl.camera import Camera, look_at
from sppl.lang import load_model
from sppl.lang.pretty import format_source
from sppl.simulate import sample_objects

MODELS = Path(__file__).resolve().parent.parent / "models"
NEW = ("blocks", "tabletop", "shapes_plus")
# Where a camera sees each model's objects from: (eye, target).
VIEWS = {
    "shapes": ((6, -6, 5), (0, 0, 0)),
    "blocks": ((6, -6, 5), (0, 0, 0)),
    "tabletop": ((1.2, -1.2, 1.6), (0, 0, 0.75)),
    "shapes_plus": ((7, -7, 6), (0, 0, 0)),
}


@pytest.fixture(scope="module", params=sorted(VIEWS))
def model(request):
    return load_model(MODELS / f"{request.param}.scn")


def test_every_model_file_is_listed_here():
    assert {p.stem for p in MODELS.glob("*.scn")} == set(VIEWS)


@pytest.mark.parametrize("name", sorted(VIEWS))
def test_every_model_is_in_canonical_form(name):
    text = (MODELS / f"{name}.scn").read_text()
    assert format_source(text) == text, f"run: sppl fmt --write models/{name}.scn"


def test_prior_draws_are_inside_every_domain(model):
    rng = np.random.default_rng(0)
    seen = set()
    for _ in range(30):
        for obj in sample_objects(model, rng):
            seen.add(obj.cls.name)
            assert math.isfinite(obj.log_prior)
            for p in obj.cls.parameters:
                assert p.domain.contains(obj.values[p.name]), (obj.cls.name, p.name)
            assert obj.parts
    assert seen == set(model.class_names)


def test_a_prior_scene_renders(model, require_gl):
    from sppl.render import Renderer

    eye, target = VIEWS[model.path.stem]
    camera = Camera("c", 64, 48, 60.0, 60.0, 32, 24, look_at(eye, target, up=(0, 0, 1)))
    renderer = Renderer(model.render)
    try:
        empty_rgb, empty_depth = renderer.render(model.static_parts, camera)
        rng = np.random.default_rng(1)
        objects = ()
        while len(objects) < 2:
            objects = sample_objects(model, rng)
        parts = [*model.static_parts, *(p for o in objects for p in o.parts)]
        rgb, depth = renderer.render(parts, camera)
    finally:
        renderer.release()
    assert rgb.shape == (48, 64, 3) and np.isfinite(depth).all()
    # The objects change some pixels, and only bring surfaces nearer.
    changed = np.abs(depth - empty_depth) > 1e-4
    assert changed.any()
    assert (depth <= empty_depth + 1e-4).all()
    if model.static_parts:  # the ground or the table is seen even without objects
        assert (empty_depth < camera.depth_max).any()


@pytest.mark.parametrize("name", NEW)
def test_prior_recovery(name):
    prior_recovery = pytest.importorskip("sppl.verify").prior_recovery

    model = load_model(MODELS / f"{name}.scn")
    report = prior_recovery(model, sweeps=3000, seed=2, reference_draws=1500)
    assert report.passed, report.table()


def test_shapes_plus_imports_the_thesis_classes_and_pairs_a_change():
    plus = load_model(MODELS / "shapes_plus.scn")
    shapes = load_model(MODELS / "shapes.scn")
    assert plus.class_names == (*shapes.class_names, "cylinder")
    for name in shapes.class_names:
        assert plus.object_class(name).parameters == shapes.object_class(name).parameters
    cube, cylinder = plus.object_class("cube"), plus.object_class("cylinder")
    assert moves.carried_parameters(cube, cylinder) == {"x": "x", "y": "y", "h": "s", "c": "c"}
    assert moves.carried_parameters(cylinder, cube) == {"x": "x", "y": "y", "s": "h", "c": "c"}
    cone = plus.object_class("cone")
    assert moves.carried_parameters(cone, cylinder) == {n: n for n in ("x", "y", "r", "h", "c")}


def test_tabletop_objects_stand_on_the_static_table():
    model = load_model(MODELS / "tabletop.scn")
    rng = np.random.default_rng(4)
    table_top = max(p.matrix[2, 3] + p.matrix[2, 2] for p in model.static_parts)
    assert table_top == pytest.approx(0.75)
    for obj in sample_objects(model, rng):
        lowest = min(p.matrix[2, 3] for p in obj.parts)
        assert lowest == pytest.approx(0.75)
    mug = model.object_class("mug")
    assert mug.parts({"x": 0, "y": 0, "a": 0, "k": 1, "c": "red"})[0].primitive.endswith("mug.obj")
    # A mug's footprint is the declared circle, scaled with the mug.
    footprint = mug.footprint({"x": 0.1, "y": 0, "a": 0.3, "k": 2.0, "c": "red"})
    radii = np.hypot(footprint[:, 0] - 0.1, footprint[:, 1])
    assert radii == pytest.approx(0.08)
