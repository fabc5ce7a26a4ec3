"""Data-driven births: where they land, that their density is normalised, and that a birth and
its reverse death have exactly opposite ratios when the proposal looks at the observations."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sppl.data.camera import Camera, focal_from_fov, look_at
from sppl.data.observations import CameraSpec, Observations
from sppl.infer import moves
from sppl.infer.chain import Sampler
from sppl.lang import load_model
from sppl.model.simulate import objects_from_dict, render_observations
from sppl.render import Renderer
from sppl.scoring.scorer import Scorer

SCENE = {
    "objects": [
        {"class": "cube", "params": {"x": 0.6, "y": -0.4, "a": 0.2, "s": 0.6, "c": "red"}},
        {"class": "sphere", "params": {"x": -0.5, "y": 0.6, "r": 0.3, "c": "blue"}},
    ],
    "noise": {"image": {"sigma": 0.05}, "depth": {"sigma": 0.05}},
}


def _camera(name, eye, size=40):
    f = focal_from_fov(size, 50)
    return Camera(name, size, size, f, f, size / 2, size / 2, look_at(eye, (0, 0, 0.3)), 8.0)


@pytest.fixture(scope="module")
def setting(require_gl, root):
    model = load_model(root / "models" / "shapes.scn")
    renderer = Renderer(model.render)
    truth = objects_from_dict(model, SCENE)
    specs = [
        CameraSpec(_camera("rgb", (3.0, -2.5, 2.4)), ("rgb",)),
        CameraSpec(_camera("depth", (-3.0, -2.0, 2.6)), ("depth",)),
    ]
    rng = np.random.default_rng(0)
    frames = render_observations(model, truth, SCENE["noise"], specs, renderer, rng)
    scorer = Scorer(model, Observations(root, frames), renderer)
    sampler = Sampler(model, scorer, np.random.default_rng(1))
    return model, truth, sampler


def test_points_fall_near_what_is_missing(setting):
    model, truth, sampler = setting
    state = sampler.make_trace(truth[:1], SCENE["noise"])  # the sphere is missing
    pts = sampler.birth.points(state)
    assert len(pts) > 20
    sphere_xy = np.array([-0.5, 0.6])
    close = np.linalg.norm(pts - sphere_xy, axis=1) < 0.8
    # Depth pixels back-project onto the sphere; RGB rays land on the ground behind it.
    assert close.mean() > 0.5
    full = sampler.make_trace(truth, SCENE["noise"])
    assert len(sampler.birth.points(full)) < 0.1 * len(pts)


def test_birth_density_is_normalised(setting):
    model, truth, sampler = setting
    state = sampler.make_trace(truth[:1], SCENE["noise"])
    sphere = model.object_class("sphere")
    others = {"r": 0.3, "c": "blue"}
    rest = sum(sphere.parameter(k).log_prob(v) for k, v in others.items())
    xs = np.linspace(-9, 9, 361)
    h = xs[1] - xs[0]
    total = 0.0
    for x in xs:
        for y in xs[::1]:
            total += math.exp(sampler.birth.log_density(sphere, {"x": x, "y": y, **others}, state) - rest)
    assert total * h * h == pytest.approx(1.0, abs=0.01)


def test_data_birth_and_its_death_are_exact_reverses(setting):
    model, truth, sampler = setting
    state = sampler.make_trace(truth[:1], SCENE["noise"])
    rng = np.random.default_rng(4)
    for _ in range(30):
        birth = moves.propose_birth(model, state, rng, sampler.birth)
        born = sampler.evaluate(state, birth)
        if born is None:  # overlapping the cube: zero prior, never accepted
            continue
        a_fwd = born.score - state.score + birth.log_q_ratio
        k = next(i for i, o in enumerate(born.objects) if o is birth.changed[0])
        gone = born.objects[k]
        death = moves.Proposal(
            "death", gone.cls.name, born.objects[:k] + born.objects[k + 1 :], born.noise, (),
            -moves.log_q_death(model, len(born.objects)),
            lambda after: moves.log_q_birth(model, gone.cls, gone.values, sampler.birth, after),
        )
        back = sampler.evaluate(born, death)
        a_rev = back.score - born.score + death.log_q_ratio + death.ratio_fn(back)
        assert a_fwd == pytest.approx(-a_rev, abs=1e-6)


def test_replace_and_its_reverse_are_exact(setting):
    """Replace object k by a data-driven fresh object; the reverse puts the old one back
    through the same intermediate state, and the two log ratios are negatives."""
    model, truth, sampler = setting
    state = sampler.make_trace(truth, SCENE["noise"])
    rng = np.random.default_rng(8)
    checked = 0
    for _ in range(30):
        p = moves.propose_replace(
            model, state, rng, sampler.birth, lambda objs: sampler.make_trace(objs, state.noise)
        )
        new = sampler.evaluate(state, p)
        if new is None:
            continue
        k = next(i for i, o in enumerate(new.objects) if o is p.changed[0])
        old = state.objects[k]
        mid = sampler.make_trace(new.objects[:k] + new.objects[k + 1 :], state.noise)
        rev = moves.Proposal(
            "replace", p.changed[0].cls.name, new.objects[:k] + (old,) + new.objects[k + 1 :],
            new.noise, (old,),
            sampler.birth.log_density(p.changed[0].cls, p.changed[0].values, mid)
            - sampler.birth.log_density(old.cls, old.values, mid),
        )
        back = sampler.evaluate(new, rev)
        a_fwd = sampler.log_alpha(state, p, new)
        a_rev = sampler.log_alpha(new, rev, back)
        assert a_fwd == pytest.approx(-a_rev, abs=1e-6)
        assert back.score == pytest.approx(state.score)
        checked += 1
    assert checked > 10


def test_objects_stand_on_the_ground_or_on_the_table(root):
    """RGB rays are followed to the height the classes' poses put objects at."""
    from sppl.infer.birth import support_height

    heights = {m: support_height(load_model(root / "models" / f"{m}.scn"))
               for m in ("shapes", "blocks", "tabletop")}
    assert heights == pytest.approx({"shapes": 0.0, "blocks": 0.0, "tabletop": 0.75})


@pytest.mark.parametrize("modality", ["rgb", "depth"])
def test_a_missing_mug_on_the_table_is_seeded_where_it_stands(require_gl, root, modality):
    """A small red mug on a wooden table, seen from above by one camera: its pixels differ
    from the table's by 0.12 to 0.2 in colour and stand 6 to 11 cm nearer, and the seed they
    give lies on the mug. With the rays followed to the floor (0.75 m below the table top)
    the RGB seed fell more than a metre away, and with the earlier thresholds (0.15 and
    0.1 m) neither camera gave one."""
    model = load_model(root / "models" / "tabletop.scn")
    renderer = Renderer(model.render)
    scene = {"objects": [{"class": "mug", "params": {"x": 0.25, "y": 0.1, "a": 0.5, "k": 0.9,
                                                     "c": "red"}},
                         {"class": "box", "params": {"x": -0.3, "y": -0.1, "a": 0.3, "w": 0.2,
                                                     "d": 0.15, "h": 0.1, "c": "green"}}],
             "noise": {"image": {"sigma": 0.02}, "depth": {"sigma": 0.01}}}
    f = focal_from_fov(80, 40)
    eye = (1.0, -0.9, 1.7)
    camera = Camera("cam", 80, 80, f, f, 40, 40, look_at(eye, (0, 0, 0.75)), 8.0)
    truth = objects_from_dict(model, scene)
    frames = render_observations(model, truth, scene["noise"], [CameraSpec(camera, (modality,))],
                                 renderer, np.random.default_rng(0))
    sampler = Sampler(model, Scorer(model, Observations(root, frames), renderer),
                      np.random.default_rng(1))
    seeds = sampler.birth.seeds(sampler.make_trace(truth[1:], scene["noise"]))
    assert len(seeds) >= 1
    assert np.linalg.norm(seeds - (0.25, 0.1), axis=1).min() < 0.08, seeds
    assert len(sampler.birth.seeds(sampler.make_trace(truth, scene["noise"]))) == 0


def test_the_depth_gap_follows_the_depth_maps_noise():
    """A sloping floor with a box on it, seen with noise 0.03 m: the estimate is within a
    tenth of it, which neither the slope nor the box's edges move; pixels at the far plane
    and invalid ones are left out."""
    from sppl.infer.birth import depth_noise

    rng = np.random.default_rng(0)
    v, u = np.mgrid[0:80, 0:80]
    depth = 2.0 + 0.02 * u + 0.01 * v
    depth[20:50, 30:60] -= 0.4
    depth[:5] = 8.0  # beyond the camera's range
    valid = np.ones(depth.shape, bool)
    valid[60:] = False
    noisy = np.where(depth < 8.0, depth + 0.03 * rng.standard_normal(depth.shape), depth)
    noisy[60:] = -1.0  # what an invalid pixel holds is never read
    assert depth_noise(noisy, valid, 8.0) == pytest.approx(0.03, rel=0.1)
    assert depth_noise(depth, None, 8.0) == pytest.approx(0.0, abs=1e-9)


def test_a_speck_apart_from_the_drawn_edges_is_kept_and_one_along_them_is_not():
    """On a grey floor with a red square drawn: a single pixel far off the render, apart
    from everything, is a speck; the same pixel beside the square's edge (its rim drawn a
    pixel off) is not, nor a glint on the square; a pixel only a little off (sensor noise)
    is not; and a blob keeps only what the erosion leaves of it, no speck of its own."""
    from sppl.infer import birth

    rendered = np.full((24, 24, 3), 0.45)
    rendered[8:14, 8:14] = (0.8, 0.15, 0.12)
    square = np.zeros((24, 24), dtype=bool)
    square[8:14, 8:14] = True

    def specks(observed):
        off = np.abs(observed - rendered).mean(axis=-1)
        blobs = birth._blobs(off > birth.COLOUR_GAP)
        return birth._specks(off > birth.COLOUR_GAP, blobs, off > birth.STRONG_COLOUR_GAP,
                             birth._edges(rendered) | square)

    apart = rendered.copy()
    apart[20, 3] = (0.1, 0.2, 0.8)
    assert np.argwhere(specks(apart)).tolist() == [[20, 3]]
    rim = rendered.copy()
    rim[10, 14] = (0.8, 0.15, 0.12)
    assert not specks(rim).any()
    glint = rendered.copy()
    glint[11, 11] = (1.0, 0.4, 0.4)
    assert not specks(glint).any()
    faint = rendered.copy()
    faint[20, 3] = 0.6
    assert not specks(faint).any()
    blob = rendered.copy()
    blob[16:22, 16:22] = (0.1, 0.2, 0.8)
    assert not specks(blob).any() and birth._blobs(
        np.abs(blob - rendered).mean(axis=-1) > birth.COLOUR_GAP).sum() == 16


def test_a_speck_beside_a_drawn_edge_is_kept_when_no_rim_of_it_shows_its_colour():
    """A green square drawn on a grey floor: a red speck two pixels across beside its edge
    (a small red cube beside a green one) is kept, since no rim of the green square can
    show red; a rim of it drawn a pixel off, the square's edge anti-aliased (a blend of
    green and grey), and a shadow's rim (a darker grey) are not; nor is a red glint on the
    square itself; and without the colours to judge by, the speck is dropped as before."""
    from sppl.infer import birth

    rendered = np.full((24, 24, 3), 0.5)
    rendered[8:14, 8:14] = (0.14, 0.65, 0.19)
    square = np.zeros((24, 24), dtype=bool)
    square[8:14, 8:14] = True

    def specks(observed, colours=True):
        off = np.abs(observed - rendered).mean(axis=-1)
        beside = birth._Beside(square, observed, rendered, birth.STRONG_COLOUR_GAP)
        return birth._specks(off > birth.COLOUR_GAP, birth._blobs(off > birth.COLOUR_GAP),
                             off > birth.STRONG_COLOUR_GAP, birth._edges(rendered) | square,
                             beside if colours else None)

    red = rendered.copy()
    red[10:12, 14:16] = (0.7, 0.08, 0.1)
    assert np.argwhere(specks(red)).tolist() == [[10, 14], [10, 15], [11, 14], [11, 15]]
    assert not specks(red, colours=False).any()
    rim = rendered.copy()
    rim[8:14, 14] = (0.12, 0.6, 0.2)
    assert not specks(rim).any()
    blend = rendered.copy()
    blend[8:14, 14] = 0.4 * np.array((0.14, 0.65, 0.19)) + 0.6 * 0.5 + (0.0, 0.2, 0.0)
    assert not specks(blend).any()
    shadow = rendered.copy()
    shadow[14:16, 8:14] = 0.2
    assert not specks(shadow).any()
    glint = rendered.copy()
    glint[10:12, 12:14] = (0.7, 0.08, 0.1)
    assert not specks(glint).any()


def test_the_cone_distance_is_zero_inside_the_cone_and_grows_outside_it():
    """A point is in the cone of two colours when it is a non-negative mix of them (a blend,
    a shade); a colour of another hue lies the mean absolute difference its nearest such mix
    leaves."""
    from sppl.infer import birth

    colours = np.array([[0.5, 0.5, 0.5], [0.1, 0.6, 0.2]])
    inside = np.array([[0.25, 0.25, 0.25], [0.3, 0.55, 0.35], [0.8, 0.8, 0.8], [0.0, 0.0, 0.0]])
    assert birth._cone_distance(inside, colours) == pytest.approx(np.zeros(4), abs=1e-9)
    red = np.array([[0.7, 0.0, 0.0]])
    # Its nearest mix, in mean absolute difference, is black (no light at all: 0.7 / 3);
    # grey scaled to its least-squares fit (0.7 / 3 a channel) leaves more.
    assert birth._cone_distance(red, colours) == pytest.approx([0.7 / 3])
    assert birth._cone_distance(np.array([[0.9, 0.1, 0.1]]), colours) > 0.3


def test_a_depth_speck_apart_from_the_drawn_outlines_is_kept_and_a_rim_is_not():
    """A floor 5 m away with a square drawn 3 m away: a column of depth pixels one wide and
    metres nearer, apart from the square, is a speck, whole; so is a pole beside the square
    that touches its outline at a few of its pixels; the square's rim drawn a pixel off is
    not, nor a column only a little nearer (within the noise's reach), nor three stray
    returns at random depths; three side by side that agree are; a blob keeps only what the
    erosion leaves of it; and a piece whose eroded pixels are too few to seed is a speck."""
    from sppl.infer import birth

    rendered = np.full((24, 24), 5.0)
    rendered[8:14, 8:14] = 3.0
    square = np.zeros((24, 24), dtype=bool)
    square[8:14, 8:14] = True

    def specks(observed):
        flagged = observed < rendered - 0.05
        return birth._depth_specks(flagged, birth._blobs(flagged), observed < rendered - 0.1,
                                   observed, birth._depth_edges(rendered, 0.05) | square)

    column = rendered.copy()
    column[16:22, 3] = np.linspace(2.0, 2.2, 6)
    assert np.argwhere(specks(column)).tolist() == [[r, 3] for r in range(16, 22)]
    pole = rendered.copy()
    pole[:, 15] = 4.0
    assert specks(pole)[:, 15].all() and specks(pole).sum() == 24
    rim = rendered.copy()
    rim[8:14, 14] = 3.0
    assert not specks(rim).any()
    faint = rendered.copy()
    faint[16:22, 3] = 4.93
    assert not specks(faint).any()
    strays = rendered.copy()
    strays[20, 18:21] = (0.3, 4.1, 2.2)
    assert not specks(strays).any()
    agreeing = rendered.copy()
    agreeing[20, 18:21] = (2.2, 2.3, 2.25)
    assert specks(agreeing).sum() == 3
    blob = rendered.copy()
    blob[16:22, 16:22] = 2.0
    assert not specks(blob).any()
    # Two squares of 3 by 3 joined by a pixel: the erosion leaves their two middles, apart,
    # neither of which seeds, so the piece is a speck.
    beads = rendered.copy()
    beads[17:20, 1:4] = beads[17:20, 5:8] = beads[18, 4] = 2.0
    assert specks(beads).sum() == 19
