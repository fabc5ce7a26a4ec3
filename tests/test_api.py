"""The Python API: a model built from sppl's exported types is the model its file compiles to,
and a run needs no folder and returns its samples."""

from __future__ import annotations

import math

import numpy as np
import pytest

import sppl
from sppl import (
    Categorical,
    Finite,
    Gamma,
    InferenceSettings,
    Model,
    Normal,
    ObjectClass,
    Parameter,
    Part,
    Periodic,
    Positive,
    Real,
    RenderSettings,
    Sensor,
    Uniform,
    rotation_z,
    scaling,
    translation,
)

TEXT = """
colours {
    red  = rgb(0.9, 0.1, 0.1)
    blue = rgb(0.1, 0.2, 0.9)
}

class ball {
    count ~ poisson(2)
    x : real ~ normal(0, 2)
    y : real ~ normal(0, 2)
    r : positive ~ gamma(2, 0.2)
    c : colour ~ categorical(red, blue)
    geometry sphere(r) at (x, y) colour c
}

class block {
    count ~ poisson(1)
    x : real ~ normal(0, 2)
    y : real ~ normal(0, 2)
    a : periodic(-pi / 4, pi / 4) ~ uniform(-pi / 4, pi / 4)
    s : positive ~ gamma(2, 0.25)
    c : colour ~ categorical(red, blue)
    geometry box(s, s, s) at (x, y) rotate a colour c
}

constraint no_overlap

sensor image {
    likelihood gaussian
    sigma : positive ~ gamma(2, 0.05)
}

render {
    background = rgb(0.5, 0.5, 0.5)
    ambient = 0.35
    light = (0.4, -0.3, 1)
}

inference {
    p_jump = 0.5
}
"""

COLOURS = {"red": (0.9, 0.1, 0.1), "blue": (0.1, 0.2, 0.9)}


def built_in_python() -> Model:
    names = tuple(COLOURS)

    # sppl's unit meshes stand on the ground plane (sppl.model.geometry.unit_mesh), so a part
    # is posed at ground level.
    def ball(v):
        r = v["r"]
        return (Part("sphere", translation(v["x"], v["y"], 0.0) @ scaling(r, r, r),
                     COLOURS[v["c"]]),)

    def block(v):
        s = v["s"]
        pose = translation(v["x"], v["y"], 0.0) @ rotation_z(v["a"]) @ scaling(s, s, s)
        return (Part("box", pose, COLOURS[v["c"]]),)

    q = math.pi / 4
    colour = Parameter("c", Finite(names), Categorical(names, (0.5, 0.5)))
    classes = (
        ObjectClass("ball", 2.0, (
            Parameter("x", Real(), Normal(0.0, 2.0)),
            Parameter("y", Real(), Normal(0.0, 2.0)),
            Parameter("r", Positive(), Gamma(2.0, 0.2)),
            colour), ball, position=("x", "y")),
        ObjectClass("block", 1.0, (
            Parameter("x", Real(), Normal(0.0, 2.0)),
            Parameter("y", Real(), Normal(0.0, 2.0)),
            Parameter("a", Periodic(-q, q), Uniform(-q, q)),
            Parameter("s", Positive(), Gamma(2.0, 0.25)),
            colour), block, position=("x", "y")),
    )
    image = Sensor("image", "gaussian", (Parameter("sigma", Positive(), Gamma(2.0, 0.05)),))
    return Model(classes, {"image": image}, InferenceSettings(p_jump=0.5),
                 RenderSettings(background=(0.5, 0.5, 0.5), ambient=0.35,
                                light=(0.4, -0.3, 1.0)),
                 colours=COLOURS, no_overlap=True)


def differences(a: Model, b: Model, draws: int = 20) -> list[str]:
    """Where two models differ: their settings, and for each class its declarations and the
    parts and prior densities of the same prior draws (a class's geometry is a function, so it
    is compared on what it does)."""
    found = []
    for field in ("inference", "render", "no_overlap", "max_objects", "region"):
        if getattr(a, field) != getattr(b, field):
            found.append(f"{field}: {getattr(a, field)} != {getattr(b, field)}")
    if dict(a.colours) != {k: tuple(v) for k, v in b.colours.items()}:
        found.append(f"colours: {a.colours} != {b.colours}")
    if list(a.sensors) != list(b.sensors):
        found.append(f"sensors: {list(a.sensors)} != {list(b.sensors)}")
    for kind in set(a.sensors) & set(b.sensors):
        sa, sb = a.sensors[kind], b.sensors[kind]
        if (sa.likelihood, dict(sa.options), sa.noise) != (sb.likelihood, dict(sb.options),
                                                           sb.noise):
            found.append(f"sensor {kind}: {sa} != {sb}")
    if a.class_names != b.class_names:
        return found + [f"classes: {a.class_names} != {b.class_names}"]
    rng = np.random.default_rng(0)
    for ca, cb in zip(a.classes, b.classes):
        for attr in ("rate", "position", "count", "max_count"):
            if getattr(ca, attr) != getattr(cb, attr):
                found.append(f"{ca.name}.{attr}: {getattr(ca, attr)} != {getattr(cb, attr)}")
        pa = [(p.name, p.domain, p.prior, p.depends_on) for p in ca.parameters]
        pb = [(p.name, p.domain, p.prior, p.depends_on) for p in cb.parameters]
        if pa != pb:
            found.append(f"{ca.name} parameters: {pa} != {pb}")
            continue
        for _ in range(draws):
            values = {p.name: p.sample(rng) for p in ca.parameters}
            parts_a, parts_b = ca.parts(values), cb.parts(values)
            same = len(parts_a) == len(parts_b) and all(
                x.primitive == y.primitive and np.allclose(x.matrix, y.matrix)
                and np.allclose(x.colour, y.colour) for x, y in zip(parts_a, parts_b))
            if not same:
                found.append(f"{ca.name} at {values}: parts {parts_a} != {parts_b}")
                break
    return found


def test_a_model_built_in_python_is_the_model_its_file_compiles_to():
    assert differences(built_in_python(), sppl.compile_model(TEXT)) == []


def test_the_comparison_sees_a_different_model():
    """The test above cannot pass on any two models: a changed rate, prior, size or setting
    is a difference."""
    from dataclasses import replace

    parsed = sppl.compile_model(TEXT)
    assert differences(built_in_python(), sppl.compile_model(TEXT.replace("poisson(2)",
                                                                           "poisson(3)")))
    assert differences(built_in_python(), sppl.compile_model(TEXT.replace("gamma(2, 0.2)",
                                                                           "gamma(2, 0.3)")))
    assert differences(built_in_python(), sppl.compile_model(TEXT.replace("box(s, s, s)",
                                                                           "box(s, s, 2 * s)")))
    assert differences(built_in_python(), replace(parsed, no_overlap=False))


def _observations(root):
    return (sppl.load_model(root / "models" / "shapes.scn"),
            sppl.load_observations(root / "examples" / "three_shapes" / "obs"))


def test_a_run_needs_no_folder_and_returns_the_samples_a_folder_run_writes(root, tmp_path,
                                                                          require_gl):
    from sppl.output.samples import read_samples

    model, obs = _observations(root)
    kept = sppl.run_chain(model, obs, None, steps=6, seed=3, progress=False)
    on_disk = sppl.run_chain(model, obs, tmp_path / "run", steps=6, seed=3, progress=False)
    assert len(kept.samples) == 6 and kept.summary["steps_done"] == 6
    assert kept.samples == on_disk.samples == read_samples(tmp_path / "run" / "samples.jsonl")
    assert kept.summary["map"] == on_disk.summary["map"]
    with pytest.raises(sppl.RunError, match="cannot be resumed"):
        sppl.run_chain(model, obs, None, steps=6, seed=3, progress=False, resume=True)


def test_several_chains_return_each_chains_samples(root, tmp_path, require_gl):
    from sppl.output.samples import read_samples

    model, obs = _observations(root)
    result = sppl.run_chains(model, obs, tmp_path / "run", chains=2, steps=4, seed=1,
                             lockstep=True, progress=False)
    assert [len(c) for c in result.chain_samples] == [4, 4]
    assert result.chain_samples[1] == read_samples(tmp_path / "run" / "chain_1" /
                                                   "samples.jsonl")
    assert result.samples == result.chain_samples[0] + result.chain_samples[1]
    kept = sppl.run_chains(model, obs, None, chains=2, steps=4, seed=1, lockstep=True,
                           progress=False)
    assert kept.chain_samples == result.chain_samples
