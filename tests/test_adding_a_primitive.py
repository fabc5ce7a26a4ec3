"""The walkthrough of docs/walkthroughs/adding-a-primitive.md, run: the dome of
examples/primitives (one module and its GLSL snippet) is registered, named by a model file,
drawn by the GL renderer as the reference ray caster draws it, scored by the fast path as by
the reference, footprinted, and offered by an installed package; and the page quotes the
files it explains as they are."""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path

import numpy as np
import pytest
from test_fast_scoring import SPECS, _assert_agree
from test_render import RED, SETTINGS, ray_cast_mismatches, top_down

from sppl import (
    Observations,
    Part,
    ReferenceScorer,
    Renderer,
    Scorer,
    compile_model,
    load_model,
    primitive_names,
    raycast,
    register_primitive,
    render_observations,
    sample_noise,
    sample_objects,
    scaling,
    translation,
)
from sppl.errors import ModelErrors
from sppl.model.geometry import footprint_of
from sppl.model.primitives import registry

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples" / "primitives"
PAGE = ROOT / "docs" / "walkthroughs" / "adding-a-primitive.md"
_module = None


def _dome_module():
    """examples/primitives/dome.py, imported once per process (importing registers it)."""
    global _module
    if _module is None:
        spec = importlib.util.spec_from_file_location("example_dome", EXAMPLE / "dome.py")
        _module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(_module)
    return _module


@pytest.fixture(scope="module")
def gl_renderer(require_gl):
    renderer = Renderer(SETTINGS)
    yield renderer
    renderer.release()


@pytest.fixture
def dome():
    shape = register_primitive(_dome_module().DOME)
    yield shape
    registry.unregister_primitive("dome")


def test_a_model_naming_an_unregistered_shape_is_an_error_that_lists_the_known_ones():
    registry.unregister_primitive("dome")
    with pytest.raises(ModelErrors) as caught:
        load_model(EXAMPLE / "domes.scn")
    message = str(caught.value)
    assert "unknown primitive `dome`" in message
    assert "box, cylinder, cone, sphere, capsule, mesh" in message


def test_a_registered_shape_compiles_and_poses_like_a_built_in_one(dome):
    assert "dome" in primitive_names()
    model = load_model(EXAMPLE / "domes.scn")
    cls = next(c for c in model.classes if c.name == "dome")
    (part,) = cls.parts({"x": 1.0, "y": -0.5, "r": 0.4, "h": 0.3, "c": "red"})
    assert part.primitive == "dome"
    np.testing.assert_allclose(part.matrix, translation(1.0, -0.5, 0.0) @ scaling(0.4, 0.4, 0.3))
    # Its footprint is its base: the 48-gon of radius 0.4 about (1, -0.5).
    corners = footprint_of([part])
    np.testing.assert_allclose(np.hypot(corners[:, 0] - 1.0, corners[:, 1] + 0.5), 0.4)
    # A wrong number of arguments is reported with the shape's declared signature.
    text = "class c {\n  geometry dome(1) colour rgb(1, 0, 0)\n}\n"
    with pytest.raises(ModelErrors, match=re.escape("dome(radius, height)")):
        compile_model(text)


@pytest.mark.parametrize("depth_type", ["z", "ray"])
def test_the_gl_renderer_draws_it_as_the_ray_caster_does(dome, gl_renderer, depth_type):
    """As test_render holds the built-in round shapes: posed domes (rotated, unevenly
    scaled) beside a box, coverage, depth and shade pixel for pixel."""
    assert ray_cast_mismatches(gl_renderer, "dome", depth_type, seed=11) <= 2


@pytest.mark.parametrize("draw", ["gl", "raycast"])
def test_seen_from_above_its_depth_is_the_half_ellipsoid(dome, gl_renderer, draw):
    """Geometry alone: from 5 m straight above, the ray through pixel (u, v) is t (x, y, -1)
    with x = (u - 32) / f, y = (32 - v) / f, t its z-depth; it meets the dome of radius r and
    height h where t^2 (x^2 + y^2) / r^2 + (5 - t)^2 / h^2 = 1, at the smaller root."""
    camera = top_down()
    r, h = 1.0, 0.8
    parts = [Part("dome", scaling(r, r, h), RED)]
    render = gl_renderer.render if draw == "gl" else (lambda p, c: raycast(p, c, SETTINGS))
    _, depth = render(parts, camera)
    rows, cols = np.mgrid[0:64, 0:64] + 0.5
    x, y = (cols - 32.0) / camera.fx, (32.0 - rows) / camera.fy
    a = (x * x + y * y) / r**2 + 1.0 / h**2
    b = -5.0 / h**2
    c = 25.0 / h**2 - 1.0
    with np.errstate(invalid="ignore"):
        t = (-b - np.sqrt(b * b - a * c)) / a
    inside = np.isfinite(t)
    hit = depth < camera.depth_max
    assert np.sum(hit != inside) <= 4  # rays grazing the silhouette
    both = hit & inside
    assert both.sum() > 1000
    assert np.abs(depth[both] - t[both]).max() <= 1e-4


def test_the_fast_scorer_scores_domes_as_the_reference(dome, require_gl, tmp_path):
    model = load_model(EXAMPLE / "domes.scn")
    renderer = Renderer(model.render)
    rng = np.random.default_rng(3)
    truth = sample_objects(model, rng)
    noise = sample_noise(model, rng)
    obs = Observations(tmp_path, render_observations(model, truth, noise, SPECS, renderer, rng))
    fast, ref = Scorer(model, obs, renderer), ReferenceScorer(model, obs, renderer)
    scenes = [truth] + [sample_objects(model, rng) for _ in range(8)]
    assert any(o.cls.name == "dome" for objects in scenes for o in objects)
    for objects in scenes:
        _assert_agree(fast.statistics(objects), ref, objects, noise)
    renderer.release()


def test_an_installed_package_offers_it_through_the_entry_point_group(monkeypatch):
    registry.unregister_primitive("dome")

    class EntryPoint:
        name, value = "dome", "example_dome:DOME"

        def load(self):
            return _dome_module().DOME

    monkeypatch.setattr(registry, "entry_points", lambda group: [EntryPoint()]
                        if group == "sppl.primitives" else [])
    monkeypatch.setattr(registry, "_plugins_loaded", False)
    try:
        model = load_model(EXAMPLE / "domes.scn")
        assert {c.name for c in model.classes} == {"dome", "block"}
    finally:
        registry.unregister_primitive("dome")


def test_registration_refuses_an_incomplete_shape(dome):
    from sppl import Primitive, SpplError

    with pytest.raises(SpplError, match="already registered"):
        register_primitive(Primitive("dome", ("radius",), mesh=dome.mesh, scale=dome.scale))
    with pytest.raises(SpplError, match="numpy twin"):
        register_primitive(Primitive("half", ("radius",), mesh=dome.mesh,
                                     scale=lambda s: (s[0],) * 3, glsl=dome.glsl))
    with pytest.raises(SpplError, match="must define `bool half_hit"):
        register_primitive(Primitive("half", ("radius",), mesh=dome.mesh,
                                     scale=lambda s: (s[0],) * 3, glsl=dome.glsl, hits=dome.hits))
    with pytest.raises(SpplError, match="identifier"):
        register_primitive(Primitive("mesh", ("file",), mesh=dome.mesh, scale=dome.scale))


def test_the_page_quotes_the_example_files_as_they_are():
    """Every code block of the walkthrough that says which file it is from (a first line
    ``# examples/...`` or ``// examples/...``) is that file's text, verbatim."""
    blocks = re.findall(r"```[a-z]*\n(.*?)```", PAGE.read_text(), flags=re.DOTALL)
    quoted = 0
    for block in blocks:
        first, _, rest = block.partition("\n")
        match = re.fullmatch(r"(?:#|//) (examples/\S+)(?: \(excerpt\))?", first.strip())
        if match is None:
            continue
        text = (ROOT / match.group(1)).read_text()
        assert rest in text, f"the page's quote of {match.group(1)} is not the file's text"
        quoted += 1
    assert quoted >= 3
