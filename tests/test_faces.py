"""The face move (sppl/infer/faces.py): a size stepped with the place so that one side of the
object stays put. Symmetric through a shear, so checked by the move checks (a step and its
reverse), prior recovery and Geweke; prior recovery fails when the side kept follows the step's
sign; and on sppl's render of a table the move shortens a box held too long, which the chain
without it does not."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from false_alarms import EACH
from test_fitted_birth import observed_scene
from test_verify import seen_world

from sppl import verify
from sppl.infer import faces


def with_faces(model, steps=1):
    return dataclasses.replace(model, inference=dataclasses.replace(model.inference,
                                                                    face_steps=steps))


def _box(root):
    from sppl.lang import load_model

    return load_model(root / "models" / "tabletop.scn").object_class("box")


def test_a_box_reaches_half_its_side_either_way_along_that_side(root):
    """A box's width moves the corners half the width along the box's own axis, either way;
    its height moves none sideways; neither depends on the width, the depth or the place."""
    box = _box(root)
    values = {"x": 0.3, "y": -0.1, "a": 0.4, "w": 0.1, "d": 0.2, "h": 0.1, "c": "kraft"}
    axis = 0.5 * np.array([math.cos(0.4), math.sin(0.4)])
    for v in (values, {**values, "w": 0.25, "x": -0.2, "y": 0.3}):
        got = faces.reaches(box, v, "w")
        assert np.allclose(sorted(got.tolist()), sorted([axis.tolist(), (-axis).tolist()]))
        side = 0.5 * np.array([-math.sin(0.4), math.cos(0.4)])
        assert np.allclose(sorted(faces.reaches(box, v, "d").tolist()),
                           sorted([side.tolist(), (-side).tolist()]))
        assert len(faces.reaches(box, v, "h")) == 0
    assert faces.face_parameters(box) == ("w", "d", "h")


def test_a_cube_reaches_its_four_corners(root):
    """A cube's side moves every corner outward: four reaches, the half-diagonals."""
    from sppl.lang import load_model

    cube = load_model(root / "models" / "shapes.scn").object_class("cube")
    got = faces.reaches(cube, {"x": 1.0, "y": 2.0, "a": 0.0, "s": 0.3, "c": "red"}, "s")
    assert np.allclose(sorted(got.tolist()), [[-0.5, -0.5], [-0.5, 0.5], [0.5, -0.5], [0.5, 0.5]])


def test_a_face_step_keeps_one_side_and_its_reverse_undoes_it(root):
    """The box grown by delta along its width with the place moved by -delta u: the corners
    on the side u points to stay where they were, and the reverse gives the box back with
    log ratios that cancel."""
    from sppl.infer.chain import Sampler
    from sppl.lang import load_model
    from sppl.model.trace import make_object
    from sppl.render.bounds import world_corners
    from sppl.scoring.scorer import PriorScorer
    from sppl.verify.reverses import check_reverse

    model = with_faces(load_model(root / "models" / "tabletop.scn"))
    box = model.object_class("box")
    values = {"x": 0.1, "y": 0.0, "a": 0.7, "w": 0.1, "d": 0.2, "h": 0.1, "c": "kraft"}
    sampler = Sampler(model, PriorScorer(), np.random.default_rng(0))
    trace = sampler.initial_trace((make_object(model, box, values),))
    reach = faces.reaches(box, values, "w")
    for side in range(len(reach)):
        p = faces.propose_face(model, trace, 0, "w", None, side=side, delta=0.05)
        before = world_corners(trace.objects[0].parts)[:2].T
        after = world_corners(p.objects[0].parts)[:2].T
        kept = (before - (values["x"], values["y"])) @ reach[side] > 0
        assert kept.sum() == 4 and np.allclose(before[kept], after[kept])
        assert not np.allclose(before[~kept], after[~kept])
        forward, backward, same = check_reverse(sampler, trace, p)
        assert same and abs(forward + backward) < 1e-9


def test_every_face_move_and_its_reverse(require_gl):
    report = verify.move_checks(with_faces(seen_world()), states=20, seed=5)
    assert report.passed, report.table()
    assert "face: reverse undoes it" in {r.quantity for r in report.rows}


def test_the_move_checks_see_a_reach_that_changes_with_the_step(monkeypatch):
    """Reaches that grow with the size itself make the step back land elsewhere (the move
    would not be a shear): the move checks report the face move as having no reverse."""
    real = faces.reaches
    monkeypatch.setattr(faces, "reaches",
                        lambda cls, values, name: real(cls, values, name) * values[name])
    report = verify.move_checks(with_faces(seen_world()), states=10, seed=5, observe=False)
    assert not report.passed
    row = next(r for r in report.rows if r.quantity == "face: reverse undoes it")
    assert "no reverse" in row.observed and not row.ok


@pytest.mark.false_alarm(EACH)
def test_prior_recovery_with_face_moves(false_alarm):
    """Without observations the chain with face moves reproduces the prior (counts
    chi-square, marginals KS; false alarm at the marker's rate, Holm)."""
    report = verify.prior_recovery(with_faces(seen_world(), 4), sweeps=8000, seed=3,
                                   alpha=false_alarm)
    assert report.passed, report.table()
    assert report.row("face moves accepted").ok


def test_prior_recovery_sees_a_side_kept_by_the_step_sign(monkeypatch):
    """A face move that keeps the first side when it grows the object and the other when it
    shrinks it moves the place the same way at every step: its reverse (the same side, the
    step back) is never proposed, and the chain drifts off the prior; the check fails."""
    real = faces.propose_face

    def by_sign(model, trace, k, name, rng, factor=1.0, side=None, delta=None):
        if side is None and rng is not None:
            delta = trace.objects[k].cls.parameter(name).proposal_scale * factor * float(
                rng.standard_normal())
            side = 0 if delta > 0 else len(faces.reaches(trace.objects[k].cls,
                                                         trace.objects[k].values, name)) - 1
        return real(model, trace, k, name, rng, factor, side, delta)

    monkeypatch.setattr(faces, "propose_face", by_sign)
    report = verify.prior_recovery(with_faces(seen_world(), 4), sweeps=8000, seed=3, alpha=EACH)
    assert not report.passed, report.table()


@pytest.mark.false_alarm(EACH)
def test_geweke_with_face_moves(false_alarm, require_gl):
    """False alarm at the marker's rate (Holm)."""
    report = verify.geweke(with_faces(seen_world()), chains=100, length=12, seed=7, size=8,
                           mc_draws=4000, alpha=false_alarm)
    assert report.passed, report.table()
    assert report.row("face moves accepted").ok


def _long_box(root, tmp_path):
    """tabletop.scn's prior scene 6 (benchmarks/prior_scenes.py), observed as the benchmark
    observes it, and the state a chain held there: the second green box 5 cm too long, its
    near end right (what each sampler is made with, the truth, and that state)."""
    from sppl.infer.chain import Sampler
    from sppl.model.trace import make_object
    from sppl.render import Renderer
    from sppl.scoring.scorer import Scorer

    scene = {"objects": [
        {"class": "mug", "params": {"x": 0.0198, "y": -0.2262, "a": -0.9649, "k": 0.7555,
                                    "c": "white"}},
        {"class": "box", "params": {"x": 0.2537, "y": -0.2095, "a": -0.3771, "w": 0.1999,
                                    "d": 0.0898, "h": 0.1174, "c": "green"}},
        {"class": "box", "params": {"x": 0.3512, "y": -0.1018, "a": 0.9582, "w": 0.1263,
                                    "d": 0.0487, "h": 0.1500, "c": "green"}}],
        "noise": {"image": {"sigma": 0.05}, "depth": {"sigma": 0.01}}}
    model, truth, noise, obs = observed_scene(root, tmp_path, "tabletop", scene, 2032)

    def sampler(steps):
        m = dataclasses.replace(model, inference=dataclasses.replace(
            model.inference, face_steps=steps, p_jump=0.0))
        return Sampler(m, Scorer(m, obs, Renderer(m.render)), np.random.default_rng(1))

    box = truth[2]
    long = {**box.values, "a": box.values["a"] - math.pi / 2, "w": box.values["d"],
            "d": box.values["w"] + 0.055}
    axis = np.array([-math.sin(long["a"]), math.cos(long["a"])])  # the depth's axis
    long["x"], long["y"] = np.array([box.values["x"], box.values["y"]]) + 0.0275 * axis
    held = truth[:2] + (make_object(model, box.cls, long),)
    return sampler, truth, noise, held


def test_a_box_held_too_long_is_shortened_from_its_wrong_end(require_gl, root, tmp_path):
    """From the state the benchmark's chain held (the box 5.5 cm too long, its near end
    right), 150 sweeps of parameter moves with face moves bring its length within 1.5 cm and
    its centre within 1 cm of the truth's; without face moves it stays more than 3 cm too
    long."""
    make_sampler, truth, noise, held = _long_box(root, tmp_path)
    true_box = truth[2].values
    for steps in (1, 0):
        sampler = make_sampler(steps)
        trace = sampler.make_trace(held, noise)
        for _ in range(150):
            trace = sampler.sweep(trace)
        box = trace.objects[2].values
        # The chain's box is the true one turned a quarter: its depth is the true width.
        length = box["d"] if abs(math.cos(box["a"] - true_box["a"])) < 0.5 else box["w"]
        off = math.hypot(box["x"] - true_box["x"], box["y"] - true_box["y"])
        if steps:
            assert abs(length - true_box["w"]) < 0.015 and off < 0.01, box
        else:
            assert length - true_box["w"] > 0.03 and off > 0.015, box
