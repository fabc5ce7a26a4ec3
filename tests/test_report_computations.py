"""What `sppl report` computes, checked on hand-made samples and scenes whose answers are known:
the occupancy grid, the matching of sample objects to MAP objects (the marginals), the MAP
against the truth, the acceptance table, R-hat and ESS, and the trace plot's lines.

No rendering and no sampling: tests/test_report.py runs the whole report end to end.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

from sppl.lang import load_model
from sppl.output.posterior import Chain, RunFiles, diagnostics, posterior_arrays
from sppl.output.report import (
    CHAIN_COLOURS,
    MATCH_RADIUS,
    _acceptance_table,
    acceptance_html,
    diagnostics_html,
    match_to_map,
    occupancy_grid,
    trace_plot,
    truth_rows,
)

ROOT = Path(__file__).resolve().parent.parent
CLASSES = ["cube", "cone", "sphere"]


@pytest.fixture(scope="module")
def model():
    return load_model(ROOT / "models" / "shapes.scn")


def cube(x, y, s=1.0, a=0.0, c="red"):
    return {"class": "cube", "params": {"x": x, "y": y, "a": a, "s": s, "c": c}}


def sphere(x, y, r=0.25, c="blue"):
    return {"class": "sphere", "params": {"x": x, "y": y, "r": r, "c": c}}


def cone(x, y, r=0.2, h=0.5, c="green"):
    return {"class": "cone", "params": {"x": x, "y": y, "r": r, "h": h, "c": c}}


def scene(*objects):
    return {"objects": list(objects)}


# -- the occupancy grid --------------------------------------------------------------------------

EXTENT = (-2.0, 2.0, -2.0, 2.0)
CELLS = 40  # 0.1 m cells: their centres are at -1.95, -1.85, ..., never on a cube's edge


def centres():
    c = np.linspace(-2.0, 2.0, CELLS + 1)[:-1] + 0.05
    return np.meshgrid(c, c)  # rows are y, as the grid's


def test_occupancy_is_the_fraction_of_samples_whose_footprints_cover_each_cell(model):
    a, b, ball = cube(0.0, 0.0), cube(0.2, 0.0), sphere(1.5, 1.5)
    samples = [scene(a), scene(a, ball), scene(a, b), scene()]  # b overlaps a in one sample
    grid = occupancy_grid(model, samples, EXTENT, cells=CELLS)
    gx, gy = centres()
    in_a = (np.abs(gx) < 0.5) & (np.abs(gy) < 0.5)
    in_b = (np.abs(gx - 0.2) < 0.5) & (np.abs(gy) < 0.5)
    near_ball = np.hypot(gx - 1.5, gy - 1.5)
    assert grid.shape == (CELLS, CELLS)
    # Under a: three samples of four, the one holding both a and b counted once.
    assert np.all(grid[in_a] == 0.75)
    assert np.all(grid[in_b & ~in_a] == 0.25)  # b alone: one sample of four
    assert np.all(grid[near_ball < 0.2] == 0.25)
    assert np.all(grid[~in_a & ~in_b & (near_ball > 0.3)] == 0.0)
    assert in_a.sum() == 100 and (in_b & ~in_a).sum() == 20  # the cells meant, 0.1 m apart


def test_occupancy_follows_the_rotated_footprint(model):
    diamond = cube(0.0, 0.0, s=1.0, a=math.pi / 4)  # corners 0.707 m out along the axes
    grid = occupancy_grid(model, [scene(diamond)], EXTENT, cells=CELLS)
    gx, gy = centres()
    inside = np.abs(gx) + np.abs(gy) < 1 / math.sqrt(2) - 0.01
    outside = np.abs(gx) + np.abs(gy) > 1 / math.sqrt(2) + 0.01
    assert np.all(grid[inside] == 1.0) and np.all(grid[outside] == 0.0)
    # A point inside the diamond but outside the unrotated square, and the reverse.
    row, col = 20, 26  # the cell centred at (0.65, 0.05)
    assert (gx[row, col], gy[row, col]) == pytest.approx((0.65, 0.05))
    assert grid[row, col] == 1.0
    row, col = 24, 24  # (0.45, 0.45)
    assert grid[row, col] == 0.0


# -- matching sample objects to the MAP's (what each marginal is taken over) ----------------------


def test_each_map_object_gets_the_nearest_object_of_its_class_within_the_radius(model):
    mp = [cube(0.0, 0.0), sphere(2.0, 0.0)]
    near_cube, near_sphere, second_cube = cube(0.1, 0.0), sphere(2.1, 0.0), cube(0.45, 0.0)
    closest = cube(0.05, 0.0)
    samples = [
        scene(near_sphere, near_cube),  # listed in another order than the MAP's
        scene(second_cube, closest),  # two candidates: the nearer one
        scene(sphere(0.0, 0.0)),  # where the cube is, but a sphere: no match for either
        scene(cube(MATCH_RADIUS + 0.1, 0.0)),  # a cube too far away
        scene(),
    ]
    cubes, spheres = match_to_map(model, mp, samples)
    assert cubes == [near_cube, closest, None, None, None]
    assert spheres == [near_sphere, None, None, None, None]


def test_matching_is_an_optimal_assignment_not_first_come(model):
    """MAP cubes at 0 and 0.4, a sample's cubes at 0.25 and -0.35. Taking the nearest for the
    first MAP cube would leave the second none (-0.35 is 0.75 from it); the assignment pairs
    both, and uses no sample object twice."""
    mp = [cube(0.0, 0.0), cube(0.4, 0.0)]
    o1, o2 = cube(0.25, 0.0), cube(-0.35, 0.0)
    first, second = match_to_map(model, mp, [scene(o1, o2), scene(cube(0.2, 0.0))])
    assert first[0] == o2 and second[0] == o1
    assert (first[1] is None) != (second[1] is None)  # one sample cube, one match


# -- the MAP against the truth -------------------------------------------------------------------


def test_map_against_truth_gives_position_and_size_errors_of_each_matched_pair(model):
    mp = [cube(0.1, 0.0, s=0.5, a=0.3, c="red"), sphere(2.0, 0.2, r=0.4, c="blue")]
    truth = [sphere(2.0, 0.0, r=0.3, c="green"), cube(0.0, 0.0, s=0.6, a=0.1, c="red"),
             cone(5.0, 5.0)]
    t = truth_rows(model, mp, truth)
    rows = {r["true_class"]: r for r in t["rows"]}
    assert set(rows) == {"cube", "sphere"}
    assert rows["cube"]["map"] == 0 and rows["cube"]["true"] == 1
    assert rows["cube"]["position_error"] == pytest.approx(0.1)
    assert rows["cube"]["size_errors"] == pytest.approx({"s": -0.1})  # the angle a is no size
    assert rows["cube"]["categories"] == {"c": ("red", "red")}
    assert rows["sphere"]["position_error"] == pytest.approx(0.2)
    assert rows["sphere"]["size_errors"] == pytest.approx({"r": 0.1})
    assert rows["sphere"]["categories"] == {"c": ("blue", "green")}
    assert t["missed"] == [truth[2]] and t["extra"] == []
    e = t["errors"]
    assert (e.n_true, e.n_estimated, e.wrong_class, e.wrong_category) == (3, 2, 0, 1)
    assert e.max_position_error == pytest.approx(0.2) and not e.correct()


def test_map_against_truth_with_a_wrong_class_and_an_extra_object(model):
    mp = [sphere(0.0, 0.05, r=0.3, c="red"), cone(-3.0, 0.0)]
    truth = [cube(0.0, 0.0, s=0.6, c="red")]
    t = truth_rows(model, mp, truth)
    [row] = t["rows"]
    assert (row["true_class"], row["map_class"]) == ("cube", "sphere")
    assert row["position_error"] == pytest.approx(0.05)
    assert row["size_errors"] == {}  # a sphere has no side s to compare
    assert t["extra"] == [mp[1]] and t["missed"] == []
    assert t["errors"].wrong_class == 1


def test_the_truth_table_shows_the_errors(model):
    from sppl.output.report import truth_html

    page = truth_html(model, [cube(0.1, 0.0, s=0.5)], [cube(0.0, 0.0, s=0.6), cone(5.0, 5.0)])
    assert "MAP 1, true 2" in page and "<b>not right</b>" in page
    assert "<td>0.100</td><td>s: -0.100</td>" in page
    assert "<td>missed</td>" in page


# -- acceptance rates ----------------------------------------------------------------------------

MOVES = {
    "parameters/cube": {"proposed": 100, "accepted": 50},
    "birth/sphere": {"proposed": 4, "accepted": 1},
    "noise/image": {"proposed": 20, "accepted": 5},
    "birth/cube": {"proposed": 10, "accepted": 3},
    "death/cube": {"proposed": 0, "accepted": 0},
}


def cells(page: str) -> dict[str, list[str]]:
    """The acceptance table: move -> the text of its cells, in the header's order."""
    rows = re.findall(r"<tr><th>([^<]+)</th>((?:<td>.*?</td>)*)</tr>", page)
    return {move: re.findall(r"<td>(.*?)</td>", tds) for move, tds in rows}


def test_acceptance_per_move_type_and_per_class():
    table = _acceptance_table({"acceptance_by_class": MOVES})
    assert list(table) == ["birth", "death", "parameters", "noise"]
    more = {**MOVES, "refit/cube": {"proposed": 1, "accepted": 0},
            "face/cube": {"proposed": 8, "accepted": 2}}
    assert list(_acceptance_table({"acceptance_by_class": more})) == [
        "birth", "death", "parameters", "face", "noise", "refit"]
    assert table["birth"] == {"sphere": (4, 1), "cube": (10, 3), "all": (14, 4)}
    assert table["noise"] == {"image": (20, 5), "all": (20, 5)}
    page = acceptance_html({"acceptance_by_class": MOVES})
    # Two tables, the object moves by class and the noise moves by sensor: no column that is
    # empty in every row (one table for both had a column per class and per sensor).
    objects, noise = page.split("</table>")[:2]
    assert re.findall(r"<th>([^<]+)</th>", objects.split("</tr>")[0]) == \
        ["move \\ class", "cube", "sphere", "all"]
    assert re.findall(r"<th>([^<]+)</th>", noise.split("</tr>")[0]) == \
        ["move \\ sensor", "image", "all"]
    got = cells(page)
    assert got["birth"] == ["0.300 <small>(3/10)</small>", "0.250 <small>(1/4)</small>",
                            "0.286 <small>(4/14)</small>"]
    assert got["death"] == ["–", "–", "–"]  # never proposed: no rate
    assert got["parameters"] == ["0.500 <small>(50/100)</small>", "–",
                                 "0.500 <small>(50/100)</small>"]
    assert got["noise"] == ["0.250 <small>(5/20)</small>", "0.250 <small>(5/20)</small>"]
    assert all(all(c for c in row) for row in got.values())


def test_the_summary_block_wraps_instead_of_running_off_the_side():
    from sppl.output.report import CSS

    pre = re.search(r"pre \{([^}]*)\}", CSS).group(1)
    assert "white-space: pre-wrap" in pre and "overflow-x" not in pre


def test_marginal_tick_labels_do_not_overlap(monkeypatch, tmp_path):
    """A narrow panel over a narrow range (-0.24 to -0.16) had five labels run together."""
    import sppl.output.report as report

    figures = []
    monkeypatch.setattr(report, "_save", lambda fig, folder, name: figures.append(fig) or name)
    model = load_model(Path(__file__).resolve().parent.parent / "models" / "shapes.scn")
    cube = {"class": "cube", "params": {"x": 0.29, "y": -0.216, "a": 0.261, "s": 0.699,
                                        "c": "red"}}
    # The spread of the report that showed it: y from -0.24 to -0.16, s from 0.675 to 0.705.
    t = np.linspace(0.0, 1.0, 60)
    samples = [{"step": i, "objects": [{"class": "cube", "params": {
        "x": 0.28 + 0.06 * u, "y": -0.24 + 0.08 * u, "a": 0.05 + 0.2 * u, "s": 0.675 + 0.03 * u,
        "c": "red"}}]} for i, u in enumerate(t)]
    report.marginal_figures(model, [cube], samples, None, tmp_path)
    (fig,) = figures
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    renderer = FigureCanvasAgg(fig).get_renderer()
    fig.draw(renderer)
    for ax in fig.axes:
        boxes = [t.get_window_extent(renderer) for t in ax.get_xticklabels() if t.get_text()]
        # At least a label's height of space between neighbours (the old ticks left 2 px).
        assert all(b.x0 - a.x1 >= a.height for a, b in zip(boxes, boxes[1:])), \
            [t.get_text() for t in ax.get_xticklabels()]


# -- R-hat, bulk and tail ESS; the traces ---------------------------------------------------------


def synthetic_run(n_chains=3, steps=200, burn=50, seed=0) -> RunFiles:
    """Chains of made-up samples: a random walk of the number of objects and the log joint."""
    rng = np.random.default_rng(seed)
    chains = []
    for c in range(n_chains):
        samples, n = [], 1
        for step in range(1, steps + 1):
            n = int(np.clip(n + rng.integers(-1, 2), 0, 4))
            objects = [cube(float(k), 0.0) for k in range(n)]
            score = 100.0 * n + rng.normal(0, 5) + 3 * c
            samples.append({"step": step, "score": score, "log_likelihood": score - 10,
                            "objects": objects,
                            "noise": {"image": {"sigma": 0.05 + 0.01 * rng.random()}}})
        summary = {"class_counts": {k: {} for k in CLASSES}, "burn": burn}
        chains.append(Chain(Path(f"chain_{c}"), {}, summary, samples))
    summary = {"class_counts": {k: {} for k in CLASSES}, "burn": burn}
    return RunFiles(Path("run"), {"steps": steps}, summary, chains)


def test_rhat_and_bulk_and_tail_ess_of_each_label_invariant_quantity():
    import arviz_stats

    run = synthetic_run()
    post = posterior_arrays(run)
    assert post.n_chains == 3 and post.n_draws == 151  # steps 50..200 of each chain
    diag = diagnostics(post)
    assert set(diag) == {"n_objects", "count[cube]", "count[cone]", "count[sphere]",
                         "log joint", "log likelihood", "image_sigma"}
    assert diag["count[cone]"] == {"mean": 0.0, "sd": 0.0, "rhat": None, "ess_bulk": None,
                                   "ess_tail": None}  # never changes: nothing to measure
    lp = post.stats["lp"]
    for name in ("n_objects", "log joint", "image_sigma"):
        d = diag[name]
        assert d["rhat"] is not None and d["ess_bulk"] > 0 and d["ess_tail"] > 0, name
    try:  # the ESS of the 5% and 95% quantiles, as sppl.output.posterior asks for it
        tail = arviz_stats.ess(lp, chain_axis=0, draw_axis=1, method="tail", prob=(0.05, 0.95))
    except TypeError:  # arviz-stats 1.x takes no prob
        tail = arviz_stats.ess(lp, chain_axis=0, draw_axis=1, method="tail")
    assert diag["log joint"]["ess_tail"] == pytest.approx(float(tail))
    assert diag["log joint"]["ess_tail"] != pytest.approx(diag["log joint"]["ess_bulk"])
    assert diag["log joint"]["ess_bulk"] == pytest.approx(float(
        arviz_stats.ess(lp, chain_axis=0, draw_axis=1, method="bulk")))
    assert diag["log joint"]["rhat"] == pytest.approx(float(
        arviz_stats.rhat(lp, chain_axis=0, draw_axis=1)))

    page = diagnostics_html(diag, post.n_chains)
    header = re.findall(r"<th>([^<]+)</th>", page.split("</tr>")[0])
    assert header == ["quantity", "mean", "sd", "R-hat", "bulk ESS", "tail ESS"]
    rows = dict(re.findall(r"<tr[^>]*><th>([^<]+)</th>(.*?)</tr>", page))
    for name, d in diag.items():
        values = re.findall(r"<td>(.*?)</td>", rows[name])
        tail = "–" if d["ess_tail"] is None else format(d["ess_tail"], ".0f")
        assert values[-1] == tail, name


@pytest.mark.parametrize("n_chains", [1, 3])
def test_the_trace_plot_has_one_line_a_chain_in_every_row(n_chains):
    run = synthetic_run(n_chains=n_chains)
    fig = trace_plot(run)
    axes = fig.axes
    assert [ax.get_ylabel() for ax in axes] == ["log joint", "number of objects", "image.sigma"]
    for row, ax in enumerate(axes):
        lines = [line for line in ax.get_lines() if line.get_color() in CHAIN_COLOURS]
        assert len(lines) == n_chains, ax.get_ylabel()
        for i, (line, chain) in enumerate(zip(lines, run.chains)):
            assert line.get_color() == CHAIN_COLOURS[i]
            series = [[s["score"] for s in chain.samples],
                      [len(s["objects"]) for s in chain.samples],
                      [s["noise"]["image"]["sigma"] for s in chain.samples]][row]
            assert np.array_equal(line.get_xdata(), [s["step"] for s in chain.samples])
            assert np.array_equal(line.get_ydata(), series)
        burn = [line for line in ax.get_lines() if line not in lines]
        assert len(burn) == 1 and list(burn[0].get_xdata()) == [50, 50]  # the end of burn-in
    if n_chains > 1:
        legend = [t.get_text() for t in axes[1].get_legend().get_texts()]
        assert legend == [f"chain {i}" for i in range(n_chains)]
