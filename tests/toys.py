"""Small models built in Python with sppl's public API, for tests of the engine that need no
model file."""

from __future__ import annotations

import numpy as np

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
    PriorScorer,
    Real,
    Sampler,
    Sensor,
    Uniform,
    rotation_z,
    scaling,
    translation,
)

COLOURS = ("red", "blue")


def _sphere(v):
    r = v["r"]
    return (Part("sphere", translation(v["x"], v["y"], 0) @ scaling(r, r, r), (1.0, 0.0, 0.0)),)


def _box(v):
    s = v["s"]
    m = translation(v["x"], v["y"], 0) @ rotation_z(v["a"]) @ scaling(s, s, s)
    return (Part("box", m, (0.0, 0.0, 1.0)),)


def ball_class(name="ball", rate=2.0) -> ObjectClass:
    return ObjectClass(
        name,
        rate,
        (
            Parameter("x", Real(), Normal(0.0, 2.0), 0.8),
            Parameter("y", Real(), Normal(0.0, 2.0), 0.8),
            Parameter("r", Positive(), Gamma(2.0, 0.2), 0.1),
            Parameter("c", Finite(COLOURS), Categorical(COLOURS, (0.3, 0.7))),
        ),
        _sphere,
    )


def block_class(name="block", rate=1.0) -> ObjectClass:
    q = np.pi / 4
    return ObjectClass(
        name,
        rate,
        (
            Parameter("x", Real(), Normal(0.0, 2.0), 0.8),
            Parameter("y", Real(), Normal(0.0, 2.0), 0.8),
            Parameter("a", Periodic(-q, q), Uniform(-q, q), 0.4),
            Parameter("s", Positive(), Gamma(2.0, 0.25), 0.1),
            Parameter("c", Finite(COLOURS), Categorical(COLOURS, (0.5, 0.5))),
        ),
        _box,
    )


def toy_model(classes, *, no_overlap=False, p_jump=1.0, noise=False) -> Model:
    sensors = {}
    if noise:
        sensors["image"] = Sensor(
            "image", "gaussian", (Parameter("sigma", Positive(), Gamma(2.0, 0.05), 0.02),)
        )
    return Model(
        tuple(classes), sensors, InferenceSettings(p_jump=p_jump), no_overlap=no_overlap
    )


def prior_sampler(model: Model, seed: int) -> Sampler:
    return Sampler(model, PriorScorer(), np.random.default_rng(seed))


_GAUSSIAN_MODELS: dict = {}


def gaussian_model(root, name):
    """models/NAME with its depth mixture replaced by a Gaussian, loaded from a copy of the
    same name (beside a link to the shipped meshes): for the tests that hold the Gaussian fast
    path against its reference on a shipped model (the mixture has twin tests of its own,
    tests/test_robust.py)."""
    import tempfile
    from pathlib import Path

    from sppl.lang import load_model

    if name not in _GAUSSIAN_MODELS:
        models = Path(root) / "models"
        text = (models / name).read_text()
        folder = Path(tempfile.mkdtemp(prefix="sppl-gaussian-"))
        (folder / "meshes").symlink_to(models / "meshes", target_is_directory=True)
        (folder / name).write_text(text.replace("likelihood mixture(outlier=0.01)",
                                                "likelihood gaussian"))
        _GAUSSIAN_MODELS[name] = load_model(folder / name)
    model = _GAUSSIAN_MODELS[name]
    assert all(s.likelihood == "gaussian" for s in model.sensors.values())
    return model
