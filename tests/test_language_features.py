"""The language's constructs beyond the basics, each down to what the engine receives:
dependent priors, integer and other domains, palettes, derived quantities, composite and mesh
geometry, footprints, static scenery, counts, imports, change correspondences, likelihoods
by name (third-party ones included), and the exactness of the moves they feed."""

from __future__ import annotations

import math
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from false_alarms import EACH, two_proportions_p
from scipy import stats
from toys import prior_sampler

from sppl.errors import ModelError, ModelErrors
from sppl.infer import moves
from sppl.lang import compile_model, load_model
from sppl.model import likelihoods
from sppl.model.distributions import (
    Beta,
    Categorical,
    Dependent,
    DiscreteUniform,
    Exponential,
    LogNormal,
    TruncatedNormal,
)
from sppl.model.domains import Integer, Periodic
from sppl.model.simulate import sample_objects
from sppl.model.trace import counts_allowed, make_object
from sppl.scoring.scorer import Scorer

ROOT = Path(__file__).resolve().parent.parent
MUG = ROOT / "models" / "meshes" / "mug.obj"


def model(body: str, path: str = "<string>"):
    return compile_model(textwrap.dedent(body), path)


def errors_of(body: str) -> list[str]:
    with pytest.raises(ModelError) as info:
        model(body)
    error = info.value
    return [e.message for e in (error.errors if isinstance(error, ModelErrors) else [error])]


CONE = """
class cone {
    count ~ poisson(1)
    r : positive ~ gamma(2, 0.25)
    let ratio = 2
    h : positive ~ uniform(r, ratio * r)
    geometry cone(r, h) colour rgb(1, 0, 0)
}
"""


# ---- distributions and domains ---------------------------------------------------------------


@pytest.mark.parametrize(
    "dist, reference",
    [
        (TruncatedNormal(0.5, 1.0, 0.0, 2.0), stats.truncnorm(-0.5, 1.5, loc=0.5, scale=1.0)),
        (TruncatedNormal(0.0, 1.0, 4.0, 6.0), stats.truncnorm(4.0, 6.0)),  # far in the tail
        (LogNormal(0.2, 0.5), stats.lognorm(0.5, scale=math.exp(0.2))),
        (Beta(2.0, 3.0), stats.beta(2.0, 3.0)),
        (Exponential(4.0), stats.expon(scale=0.25)),
    ],
)
@pytest.mark.false_alarm(EACH)
def test_new_distributions_against_scipy(false_alarm, dist, reference):
    rng = np.random.default_rng(0)
    xs = np.array([dist.sample(rng) for _ in range(4000)])
    assert stats.kstest(xs, reference.cdf).pvalue > false_alarm
    for x in xs[:20]:
        assert dist.log_prob(float(x)) == pytest.approx(reference.logpdf(x), rel=1e-9, abs=1e-9)
    low, high = dist.support()
    assert low <= xs.min() and xs.max() <= high


@pytest.mark.false_alarm(EACH)
def test_discrete_uniform_and_integer_domain(false_alarm):
    d = DiscreteUniform(2, 5)
    rng = np.random.default_rng(1)
    draws = [d.sample(rng) for _ in range(4000)]
    assert set(draws) == {2, 3, 4, 5}
    assert d.log_prob(3) == pytest.approx(-math.log(4)) and d.log_prob(6) == -math.inf
    domain = Integer(2, 5)
    assert domain.contains(2) and domain.contains(5.0) and not domain.contains(2.5)
    steps = [domain.step(5, 1.0, rng) for _ in range(4000)]
    assert set(steps) <= {2, 3, 4, 5} and 5 not in set(steps) - {5} | {0}
    # Symmetric: P(2 -> 5) = P(5 -> 2).
    forward = sum(domain.step(2, 2.0, rng) == 5 for _ in range(20000))
    backward = sum(domain.step(5, 2.0, rng) == 2 for _ in range(20000))
    assert two_proportions_p(forward, 20000, backward, 20000) > false_alarm


def test_integer_parameters_and_their_priors():
    m = model(
        """
        class stack {
            count ~ poisson(1)
            n : integer(1, 4) ~ discrete_uniform(1, 4)
            k : integer ~ poisson(2)
            geometry box(1, 1, 0.2 * n + k / 10) colour rgb(1, 1, 1)
        }
        inference { step n = 2 }
        """
    )
    n, k = m.object_class("stack").parameters
    assert n.domain == Integer(1, 4) and n.prior == DiscreteUniform(1, 4)
    assert n.proposal_scale == 2 and not n.continuous
    assert moves.parameter_blocks(m.object_class("stack")) == (("n",), ("k",))
    assert k.log_prob(3) == pytest.approx(stats.poisson.logpmf(3, 2))


def test_periodic_with_a_period_is_centred_on_zero():
    m = model(
        """
        class cube {
            count ~ poisson(1)
            a : periodic(pi / 2) ~ uniform(-pi / 4, pi / 4)
            geometry box(1, 1, 1) rotate a colour rgb(1, 1, 1)
        }
        """
    )
    assert m.object_class("cube").parameter("a").domain == Periodic(-math.pi / 4, math.pi / 4)


def test_distributions_by_name():
    m = model(
        """
        class thing {
            count ~ poisson(1)
            a : real ~ truncated_normal(0, 1, -1, 2)
            b : positive ~ lognormal(0, 0.5)
            c : interval(0, 1) ~ beta(2, 2)
            d : positive ~ exponential(rate=3)
            geometry box(b, b, b) colour rgb(c, c, c)
        }
        """
    )
    priors = [p.prior for p in m.object_class("thing").parameters]
    assert priors == [
        TruncatedNormal(0, 1, -1, 2), LogNormal(0, 0.5), Beta(2, 2), Exponential(3)
    ]


# ---- dependent priors and derived quantities -------------------------------------------------


def test_a_prior_may_depend_on_other_parameters_through_derived_quantities():
    cone = model(CONE).object_class("cone")
    r, h = cone.parameters
    assert h.depends_on == ("r",) and isinstance(h.prior, Dependent)
    assert str(h.prior) == "uniform(r, ratio * r)"
    assert h.distribution({"r": 0.5}).support() == (0.5, 1.0)
    rng = np.random.default_rng(0)
    for _ in range(200):
        v = cone.sample_prior(rng)
        assert v["r"] <= v["h"] <= 2 * v["r"]
        expected = r.log_prob(v["r"]) - math.log(v["r"])
        assert cone.log_prior(v) == pytest.approx(expected)
    # Conditional on a given r, as a change of class draws it.
    assert cone.sample_prior(rng, given={"r": 3.0})["h"] >= 3.0
    assert cone.log_prior({"r": 1.0, "h": 1.5}, only=["h"]) == pytest.approx(0.0)
    assert cone.log_prior({"r": 1.0, "h": 2.5}) == -math.inf
    with pytest.raises(TypeError, match="depends on r"):
        h.log_prob(1.0)


def test_geometry_uses_derived_quantities():
    cone = model(CONE).object_class("cone")
    (part,) = cone.parts({"r": 0.5, "h": 0.8})
    np.testing.assert_allclose(np.diag(part.matrix), (0.5, 0.5, 0.8, 1.0))


def test_a_dependent_prior_that_breaks_is_reported_with_the_values():
    cls = model(
        """
        class thing {
            count ~ poisson(1)
            r : interval(0, 2) ~ uniform(0, 2)
            h : interval(0, 1) ~ uniform(0, r)
            geometry box(1, 1, 1) colour rgb(1, 1, 1)
        }
        """
    ).object_class("thing")
    assert math.isfinite(cls.log_prior({"r": 0.5, "h": 0.2}))
    with pytest.raises(ModelError, match=r"cannot be used where r = 1.5: its values range"):
        cls.log_prior({"r": 1.5, "h": 0.2})


def test_dependent_weights_that_break_are_reported_with_the_values():
    cls = model(
        """
        class thing {
            count ~ poisson(1)
            p : interval(0, 2) ~ uniform(0, 2)
            m : categorical ~ categorical(wood: p, metal: 1 - p)
            geometry box(1, 1, 1) colour rgb(1, 1, 1)
        }
        """
    ).object_class("thing")
    assert math.isfinite(cls.log_prior({"p": 0.5, "m": "wood"}))
    with pytest.raises(ModelError, match=r"where p = 1.5: its weights must not be negative"):
        cls.log_prior({"p": 1.5, "m": "wood"})


def test_geometry_that_cannot_be_evaluated_for_some_values_says_which():
    cls = model(
        """
        class thing {
            count ~ poisson(1)
            x : real ~ normal(0, 1)
            geometry sphere(sqrt(x)) colour rgb(1, 1, 1)
        }
        """
    ).object_class("thing")
    assert cls.parts({"x": 4.0})
    with pytest.raises(ModelError, match=r"the geometry of class `thing` cannot be evaluated "
                                         r"for \{'x': -1.0\}: ") as info:
        cls.parts({"x": -1.0})
    assert info.value.span.line == 5


def test_order_inside_a_class_is_free_but_cycles_are_errors():
    m = model(
        """
        class thing {
            count ~ poisson(1)
            geometry box(w, w, top) colour rgb(1, 1, 1)
            let top = 2 * w
            h : positive ~ uniform(w, top)
            w : positive ~ gamma(2, 1)
        }
        """
    )
    assert m.object_class("thing").parameter_names == ("w", "h")  # dependency order
    messages = errors_of(
        """
        class thing {
            count ~ poisson(1)
            let a = b + 1
            let b = c * 2
            let c = a
            geometry box(a, 1, 1) colour rgb(1, 1, 1)
        }
        """
    )
    assert messages == ["`a` depends on itself: a -> b -> c -> a"]


# ---- appearance -------------------------------------------------------------------------------


def test_palettes_select_and_shade():
    m = model(
        """
        colours warm { red = rgb(0.8, 0.1, 0.1)  orange = rgb(1, 0.5, 0) }
        colours cold { blue = rgb(0.1, 0.2, 0.9) }
        class block {
            count ~ poisson(1)
            c : colour ~ categorical(warm, blue)
            m : categorical ~ categorical(matte, shiny)
            size : categorical ~ categorical(small, large)
            let height = select(size, small: 0.5, large: 1)
            geometry box(1, 1, height) colour shade(c, select(m, matte: 0.5, shiny: 2))
        }
        """
    )
    block = m.object_class("block")
    assert block.parameter("c").prior == Categorical(("red", "orange", "blue"), (1, 1, 1))
    (part,) = block.parts({"c": "orange", "m": "matte", "size": "large"})
    assert part.colour == pytest.approx((0.5, 0.25, 0.0)) and part.matrix[2, 2] == 1.0
    (part,) = block.parts({"c": "red", "m": "shiny", "size": "small"})
    assert part.colour == pytest.approx((1.0, 0.2, 0.2)) and part.matrix[2, 2] == 0.5
    assert set(m.colours) == {"red", "orange", "blue"}


def test_a_continuous_colour():
    cls = model(
        """
        class ball {
            count ~ poisson(1)
            r : interval(0, 1) ~ uniform(0, 1)
            g : interval(0, 1) ~ uniform(0, 1)
            b : interval(0, 1) ~ beta(2, 2)
            geometry sphere(0.3) colour rgb(r, g, b)
        }
        """
    ).object_class("ball")
    assert cls.parts({"r": 0.1, "g": 0.2, "b": 0.3})[0].colour == pytest.approx((0.1, 0.2, 0.3))


# ---- geometry ---------------------------------------------------------------------------------


def test_pose_scale_and_rotation_about_any_axis():
    cls = model(
        """
        class thing {
            count ~ poisson(1)
            x : real ~ normal(0, 1)
            pose at (x, 0, 1) rotate pi / 2
            geometry box(2, 1, 1) at (1, 0) rotate pi / 2 about (1, 0, 0) scale (1, 2, 3)
                colour rgb(1, 1, 1)
        }
        """
    ).object_class("thing")
    (part,) = cls.parts({"x": 5.0})
    # Unit corner (1/2, 1/2, 1): box sizes (1, 1/2, 1), scale (1, 1, 3), about x by 90 degrees
    # (y -> z, z -> -y), then by (1, 0, 0), then the pose: a quarter turn about z, then (5, 0, 1).
    corner = part.matrix @ np.array([0.5, 0.5, 1.0, 1.0])
    np.testing.assert_allclose(corner, [5.0 + 3.0, 2.0, 1.0 + 1.0, 1.0], atol=1e-12)


def test_capsule_is_a_cylinder_between_two_spheres():
    cls = model(
        """
        class pill {
            count ~ poisson(1)
            r : positive ~ gamma(2, 0.1)
            geometry capsule(r, 1) colour rgb(1, 1, 1)
        }
        """
    ).object_class("pill")
    body, bottom, top = cls.parts({"r": 0.2})
    assert [p.primitive for p in (body, bottom, top)] == ["cylinder", "sphere", "sphere"]
    np.testing.assert_allclose(body.matrix[:3, 3], (0, 0, 0.2))
    np.testing.assert_allclose(np.diag(body.matrix), (0.2, 0.2, 1.0, 1.0))
    # Sphere centres at z = r and z = r + length; the top at length + 2 r.
    assert top.matrix[2, 3] + 2 * top.matrix[2, 2] == pytest.approx(1.4)
    assert bottom.matrix[2, 3] == 0.0


def test_mesh_from_a_file_relative_to_the_model(tmp_path):
    (tmp_path / "meshes").mkdir()
    (tmp_path / "meshes" / "mug.obj").write_bytes(MUG.read_bytes())
    path = tmp_path / "cups.scn"
    path.write_text(
        'class cup {\n    count ~ poisson(1)\n    k : positive ~ gamma(2, 0.5)\n'
        '    geometry mesh("meshes/mug.obj") scale k colour rgb(1, 1, 1)\n}\n'
    )
    cls = load_model(path).object_class("cup")
    (part,) = cls.parts({"k": 2.0})
    assert part.primitive == "mesh:" + str((tmp_path / "meshes" / "mug.obj").resolve())
    footprint = cls.footprint({"k": 2.0})
    # The derived footprint is the hull of the mesh seen from above: the cup and its handle.
    assert footprint[:, 0].max() == pytest.approx(2 * 0.0755, abs=1e-3)
    assert footprint[:, 1].max() == pytest.approx(2 * 0.04, abs=2e-3)


def test_declared_footprint_and_floating_classes():
    m = model(
        """
        class table {
            count ~ poisson(1)
            x : real ~ normal(0, 2)
            y : real ~ normal(0, 2)
            pose at (x, y)
            geometry box(1, 1, 0.05) at (0, 0, 0.7) colour rgb(1, 1, 1)
            footprint rectangle(0.5, 0.5)
        }
        class balloon {
            count ~ poisson(1)
            x : real ~ normal(0, 2)
            y : real ~ normal(0, 2)
            geometry sphere(0.3) at (x, y, 2) colour rgb(1, 0, 0)
            floating
        }
        constraint no_overlap
        """
    )
    table, balloon = m.classes
    assert sorted(map(tuple, np.round(table.footprint({"x": 1, "y": 0}), 9))) == [
        (0.75, -0.25), (0.75, 0.25), (1.25, -0.25), (1.25, 0.25)
    ]
    a = make_object(m, table, {"x": 0.0, "y": 0.0})
    b = make_object(m, table, {"x": 0.4, "y": 0.0})  # declared footprints overlap
    c = make_object(m, table, {"x": 0.6, "y": 0.0})  # the tops overlap, the footprints not
    d = make_object(m, balloon, {"x": 0.0, "y": 0.0})  # floats: never in the constraint
    assert balloon.floating and d.footprint is None
    from sppl.model.trace import scene_is_valid

    assert not scene_is_valid([a, b]) and scene_is_valid([a, c]) and scene_is_valid([a, d])


def test_static_scenery_and_the_ground_are_rendered_with_every_hypothesis():
    m = model(
        """
        colours { wood = rgb(0.5, 0.3, 0.1) }
        class ball {
            count ~ poisson(1)
            geometry sphere(0.1) colour wood
        }
        ground colour rgb(0.4, 0.4, 0.4) size 10
        sensor image { likelihood gaussian  sigma : positive ~ gamma(2, 0.1) }
        static table {
            pose at (1, 0)
            geometry box(1, 1, 0.05) at (0, 0, 0.7) colour wood
        }
        """
    )
    ground, top = m.static_parts
    assert ground.primitive == "box" and ground.matrix[2, 3] == -0.01
    np.testing.assert_allclose(np.diag(ground.matrix), (10, 10, 0.01, 1))
    np.testing.assert_allclose(top.matrix[:3, 3], (1, 0, 0.7))

    class Recorder:
        """A renderer that records what it is asked to draw."""

        def __init__(self):
            self.calls = []

        def render(self, parts, camera):
            self.calls.append(list(parts))
            return np.zeros((2, 2, 3), "f4"), np.zeros((2, 2), "f4")

    from sppl.data.camera import Camera
    from sppl.data.observations import Frame, Observations

    camera = Camera("c", 2, 2, 1.0, 1.0, 1.0, 1.0, np.eye(4))
    obs = Observations(root=Path("."), frames=[Frame(camera=camera, rgb=np.zeros((2, 2, 3)))])
    recorder = Recorder()
    scorer = Scorer(m, obs, recorder)
    obj = make_object(m, m.classes[0], {})
    scorer.evaluate([obj])
    assert recorder.calls[0][:2] == [ground, top] and recorder.calls[0][2:] == list(obj.parts)


# ---- counts -----------------------------------------------------------------------------------


@pytest.mark.false_alarm(EACH)
def test_fixed_counts_and_bounds(false_alarm):
    m = model(
        """
        class lamp {
            count = 2
            x : real ~ normal(0, 3)
            geometry sphere(0.1) at (x, 0) colour rgb(1, 1, 1)
        }
        class ball {
            count ~ poisson(2)
            max_count = 3
            x : real ~ normal(0, 3)
            geometry sphere(0.1) at (x, 0) colour rgb(1, 1, 1)
        }
        constraint max_objects(4)
        """
    )
    lamp, ball = m.classes
    assert (lamp.count, lamp.rate, ball.max_count, m.max_objects) == (2, 2.0, 3, 4)
    rng = np.random.default_rng(0)
    counts = []
    for _ in range(300):
        objects = sample_objects(m, rng)
        n = [sum(o.cls is c for o in objects) for c in m.classes]
        assert n[0] == 2 and n[1] <= 2
        counts.append(n[1])
    # Ball counts are Poisson(2) truncated to at most 2 (the total bound is the tighter one).
    pmf = stats.poisson.pmf([0, 1, 2], 2.0)
    observed = np.bincount(counts, minlength=3)
    assert stats.chisquare(observed, 300 * pmf / pmf.sum()).pvalue > false_alarm
    one = [make_object(m, lamp, {"x": 0.0})]
    assert not counts_allowed(m, one) and counts_allowed(m, one * 2)


@pytest.mark.false_alarm(EACH)
def test_chain_keeps_a_fixed_count_and_recovers_a_truncated_poisson(false_alarm):
    m = model(
        """
        class lamp {
            count = 1
            x : real ~ normal(0, 3)
            geometry sphere(0.1) at (x, 0) colour rgb(1, 1, 1)
        }
        class ball {
            count ~ poisson(2.5)
            max_count = 4
            x : real ~ normal(0, 3)
            geometry sphere(0.1) at (x, 0) colour rgb(1, 1, 1)
        }
        inference { p_jump = 1 }
        """
    )
    sampler = prior_sampler(m, 3)
    trace = sampler.initial_trace()  # starts with the lamp: an empty scene has no density
    assert [o.cls.name for o in trace.objects] == ["lamp"]
    balls = []
    for i in range(12000):
        trace = sampler.sweep(trace)
        counts = trace.counts(m.class_names)
        assert counts["lamp"] == 1
        if i % 6 == 0:
            balls.append(counts["ball"])
    pmf = stats.poisson.pmf(np.arange(5), 2.5)
    observed = np.bincount(balls, minlength=5)
    assert stats.chisquare(observed, len(balls) * pmf / pmf.sum()).pvalue > false_alarm


# ---- change correspondences and the exactness of changes ------------------------------------

PAIRED = """
class post {
    count ~ poisson(1.5)
    x : real ~ normal(0, 2)
    r : positive ~ gamma(2, 0.25)
    h : positive ~ uniform(r, 3 * r)
    geometry cylinder(r, h) at (x, 0) colour rgb(1, 1, 1)
}
class crate {
    count ~ poisson(1)
    x : real ~ normal(0, 2)
    s : positive ~ gamma(3, 0.3)
    geometry box(s, s, s) at (x, 0) colour rgb(1, 1, 1)
}
change post.h <-> crate.s
inference {
    p_jump = 1
    jump_weights birth = 1, death = 1, change = 3
}
"""


def test_declared_correspondences_are_carried_both_ways():
    post, crate = model(PAIRED).classes
    assert post.correspondences == {"crate": {"h": "s"}}
    assert crate.correspondences == {"post": {"s": "h"}}
    assert moves.carried_parameters(post, crate) == {"x": "x", "s": "h"}
    assert moves.carried_parameters(crate, post) == {"x": "x", "h": "s"}


def test_a_change_and_its_reverse_with_dependent_priors_and_correspondences():
    m = model(PAIRED)
    sampler = prior_sampler(m, 0)
    rng = np.random.default_rng(5)
    checked = 0
    for _ in range(200):
        trace = sampler.initial_trace(sample_objects(m, rng))
        proposal = moves.propose_change(m, trace, rng)
        new = proposal and sampler.evaluate(trace, proposal)
        if new is None:
            continue
        forward = new.score - trace.score + proposal.log_q_ratio
        k = next(i for i, o in enumerate(new.objects) if o is proposal.changed[0])
        old, changed = trace.objects[k], new.objects[k]
        # The carried values are the old ones, under their paired names.
        for mine, theirs in moves.carried_parameters(old.cls, changed.cls).items():
            assert changed.values[mine] == old.values[theirs]
        n = len(new.objects)
        back = moves.Proposal(
            "change", changed.cls.name, new.objects[:k] + (old,) + new.objects[k + 1 :],
            new.noise, (old,),
            moves.log_q_change(m, n, old.cls, changed.cls, changed.values)
            - moves.log_q_change(m, n, changed.cls, old.cls, old.values),
        )
        returned = sampler.evaluate(new, back)
        backward = returned.score - new.score + back.log_q_ratio
        assert forward == pytest.approx(-backward)
        assert returned.score == pytest.approx(trace.score)
        checked += 1
    assert checked > 50


@pytest.mark.false_alarm(EACH)
def test_prior_recovery_through_changes_with_dependent_priors(false_alarm):
    """With no observations the chain must keep the prior: Poisson counts per class and the
    conditional h | r uniform on [r, 3r], although changes carry h from a crate's size."""
    m = model(PAIRED)
    sampler = prior_sampler(m, 11)
    trace = sampler.initial_trace(sample_objects(m, sampler.rng))
    posts, crates, ratios = [], [], []
    for i in range(15000):
        trace = sampler.sweep(trace)
        if i % 10 == 0:
            counts = trace.counts(m.class_names)
            posts.append(counts["post"])
            crates.append(counts["crate"])
            ratios += [o.values["h"] / o.values["r"] for o in trace.objects if o.cls.name == "post"]
    for draws, rate in ((posts, 1.5), (crates, 1.0)):
        top = 5
        observed = np.bincount(np.minimum(draws, top), minlength=top + 1)
        pmf = stats.poisson.pmf(np.arange(top), rate)
        expected = len(draws) * np.append(pmf, 1 - pmf.sum())
        assert stats.chisquare(observed, expected).pvalue > false_alarm / 3  # three tests
    assert stats.kstest(ratios[::3], stats.uniform(1, 2).cdf).pvalue > false_alarm / 3


# ---- imports ------------------------------------------------------------------------------------


def write(folder: Path, name: str, text: str) -> Path:
    path = folder / name
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(textwrap.dedent(text))
    return path


LIBRARY = """
colours primary { red = rgb(1, 0, 0)  blue = rgb(0, 0, 1) }
let spread = 2
class cube {
    count ~ poisson(1)
    x : real ~ normal(0, spread)
    c : colour ~ categorical(primary)
    geometry box(1, 1, 1) at (x, 0) colour c
}
class ball {
    count ~ poisson(1)
    x : real ~ normal(0, spread)
    geometry sphere(0.5) at (x, 0) colour red
}
sensor image { likelihood gaussian  sigma : positive ~ gamma(2, 0.1) }
"""


def test_import_everything_or_some_names(tmp_path):
    write(tmp_path, "lib/shapes.scn", LIBRARY)
    everything = load_model(
        write(tmp_path, "all.scn", 'import "lib/shapes.scn"\nclass cone {\n count ~ poisson(1)\n'
              ' x : real ~ normal(0, spread)\n geometry cone(1, 1) at (x, 0) colour blue\n}\n')
    )
    assert everything.class_names == ("cube", "ball", "cone")
    assert everything.sensors == {}  # sensors, render and inference settings stay behind
    assert everything.object_class("cone").parameter("x").prior.sigma == 2
    some = load_model(write(tmp_path, "some.scn", 'from "lib/shapes.scn" import cube\n'))
    assert some.class_names == ("cube",) and set(some.colours) == {"red", "blue"}


def test_the_same_class_imported_twice_is_one_class(tmp_path):
    write(tmp_path, "lib/shapes.scn", LIBRARY)
    write(tmp_path, "lib/more.scn", 'import "shapes.scn"\n')
    m = load_model(
        write(tmp_path, "main.scn", 'import "lib/shapes.scn"\nimport "lib/more.scn"\n')
    )
    assert m.class_names == ("cube", "ball")


def test_import_errors(tmp_path):
    write(tmp_path, "lib/shapes.scn", LIBRARY)
    write(tmp_path, "a.scn", 'import "b.scn"\n')
    write(tmp_path, "b.scn", 'import "a.scn"\n')
    with pytest.raises(ModelError, match=r"`a.scn` is imported in a cycle: a.scn -> b.scn -> a"):
        load_model(tmp_path / "a.scn")
    with pytest.raises(ModelError, match="has no class, constant, colour or palette `cub`"):
        load_model(write(tmp_path, "c.scn", 'from "lib/shapes.scn" import cub\n'))


# ---- sensors and likelihoods ------------------------------------------------------------------


PLUGIN = '''
import numpy as np

class Laplace:
    """A third-party likelihood: Laplace noise with scale b."""

    noise_parameters = ("b",)

    def __init__(self, **options):
        self.options = options

    def statistics(self, observed, rendered, valid=None):
        r = np.abs(observed - rendered)
        return np.array([r.size, float(r.sum())])

    def log_prob(self, stats, noise):
        n, total = stats
        return -n * np.log(2 * noise["b"]) - total / noise["b"]

    def sample(self, rendered, noise, rng):
        return rendered + rng.laplace(0.0, noise["b"], rendered.shape)
'''


def test_a_third_party_likelihood_registered_by_entry_point(tmp_path, monkeypatch):
    (tmp_path / "laplace_plugin.py").write_text(PLUGIN)
    info = tmp_path / "laplace_plugin-1.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: laplace-plugin\nVersion: 1.0\n")
    (info / "entry_points.txt").write_text("[sppl.likelihoods]\nlaplace = laplace_plugin:Laplace\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setattr(likelihoods, "_registry", dict(likelihoods._BUILTIN))
    monkeypatch.setattr(likelihoods, "_plugins_loaded", False)
    base = "class ball {\n count ~ poisson(1)\n geometry sphere(1) colour rgb(1, 1, 1)\n}\n"
    m = compile_model(
        base + "sensor depth {\n likelihood laplace(gain = 2)\n b : positive ~ gamma(2, 0.1)\n}\n"
    )
    assert m.sensors["depth"].likelihood == "laplace"
    assert likelihoods.get_likelihood("laplace", m.sensors["depth"].options).options == {"gain": 2}
    misspelt = base + "sensor depth {\n likelihood laplce\n b : positive ~ gamma(2, 1)\n}"
    assert errors_of(misspelt) == ["unknown likelihood `laplce`"]
    with pytest.raises(ModelError) as info_:
        compile_model(misspelt)
    assert info_.value.hint == "did you mean `laplace`?"
    messages = errors_of(base + "sensor depth {\n likelihood laplace\n}")
    assert messages == ["the laplace likelihood needs a prior for its noise parameter `b`"]
    sys.modules.pop("laplace_plugin", None)


# ---- syntax -------------------------------------------------------------------------------------


def test_keywords_may_name_parameters_even_after_a_geometry_line():
    m = model(
        """
        class thing {
            count ~ poisson(1)
            geometry box(size, scale, 1) colour rgb(1, 1, 1)
            size : positive ~ gamma(2, 1)
            scale : positive ~ gamma(2, 1)
            ground : real ~ normal(0, 1)
        }
        """
    )
    assert m.object_class("thing").parameter_names == ("size", "scale", "ground")


def test_an_unfinished_statement_is_reported_at_the_next_keyword():
    with pytest.raises(ModelError) as info:
        model("let a = 2 +\nclass thing {\n}\n")
    assert info.value.message == "unexpected `class`; expected an expression"
    assert (info.value.span.line, info.value.span.column) == (2, 1)
