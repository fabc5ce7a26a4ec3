"""The compiled kernels (``sppl/render/_kernels.c``) against their Python twins: an object's
draw data (``DrawCache.of_parts`` against ``of_parts_python``) and a patch's change against
its parent's terms (``PixelScorer.change`` against ``change_python``). Skipped, with the
reason, where the extension was not built; ``.ci/run`` checks that it is."""

from __future__ import annotations

import numpy as np
import pytest
from test_bounds import _cameras, _part

from sppl.errors import RenderError
from sppl.model.geometry import Part, scaling, translation
from sppl.render import kernels
from sppl.render.bounds import MARGIN, CameraBounds, unit_corners
from sppl.render.drawlist import DrawCache

pytestmark = pytest.mark.skipif(kernels.compiled is None, reason=kernels.describe())


def _singular(rng) -> Part:
    """A part flattened to no volume: not drawn, but its corners still count."""
    matrix = translation(*rng.uniform(-1, 1, 3)) @ scaling(0.5, 0.0, 0.7)
    return Part("box", matrix, (0.0, 1.0, 0.0))


@pytest.mark.parametrize("seed", range(6))
def test_draw_data_is_its_python_twin(seed):
    rng = np.random.default_rng(seed)
    for _ in range(25):
        parts = [_part(rng) for _ in range(int(rng.integers(1, 5)))]
        if rng.random() < 0.3:
            parts.insert(int(rng.integers(len(parts) + 1)), _singular(rng))
        cache = DrawCache([CameraBounds(c) for c in _cameras(rng, parts)])
        fast, twin = cache.of_parts(parts), cache.of_parts_python(parts)
        # Rows are the same float32s, in the same order, grouped in the same order.
        assert list(fast.rows) == list(twin.rows)
        assert fast.rows == twin.rows
        assert fast.rects == twin.rects
        assert fast.inside == twin.inside


def test_draw_data_gives_each_cameras_nearest_depth():
    rng = np.random.default_rng(7)
    parts = [_part(rng) for _ in range(3)]
    cache = DrawCache([CameraBounds(c) for c in _cameras(rng, parts)])
    _, _, nearest = kernels.compiled.draw_data(parts, unit_corners, cache._project,
                                               cache._limits, MARGIN)
    _, twin_nearest = cache._project_corners(np.hstack([p.matrix @ unit_corners(p.primitive)
                                                        for p in parts]))
    np.testing.assert_allclose(nearest, twin_nearest, rtol=1e-12, atol=1e-12)


def test_draw_data_hands_back_what_it_does_not_take():
    """Another dtype or shape: None, and ``of_parts`` then runs the twin."""
    rng = np.random.default_rng(3)
    part = _part(rng)
    cache = DrawCache([CameraBounds(c) for c in _cameras(rng, [part])])
    odd = Part(part.primitive, part.matrix.astype(np.float32), part.colour)
    assert kernels.compiled.draw_data([odd], unit_corners, cache._project, cache._limits,
                                      MARGIN) is None
    assert cache.of_parts([odd]) == cache.of_parts_python([odd])
    assert kernels.compiled.draw_data([part], unit_corners, cache._project[:2],
                                      cache._limits, MARGIN) is None


def test_draw_data_raises_the_twins_error_for_an_unknown_primitive():
    rng = np.random.default_rng(4)
    part = _part(rng)
    cache = DrawCache([CameraBounds(c) for c in _cameras(rng, [part])])
    bad = Part("pyramid", part.matrix, part.colour)
    for of_parts in (cache.of_parts, cache.of_parts_python):
        with pytest.raises(RenderError, match="unknown primitive 'pyramid'"):
            of_parts([bad])


class _Sums:
    """``PixelScorer.change`` and its twin without a GL context: they read nothing else."""

    from sppl.render.pixels import PixelScorer

    change, change_python, total = PixelScorer.change, PixelScorer.change_python, \
        PixelScorer.total

    def __init__(self, compiled) -> None:
        self.compiled, self._ones = compiled, np.ones(40 * 40)  # as big as a frame


@pytest.mark.parametrize("seed", range(4))
def test_change_is_its_python_twin(seed):
    rng = np.random.default_rng(seed)
    fast, twin = _Sums(kernels.compiled), _Sums(None)
    for _ in range(30):
        rows, cols = (int(x) for x in rng.integers(1, 40, 2))
        new = rng.normal(size=(rows, cols, 2)).astype("f4") * 10.0 ** rng.integers(-3, 4)
        # The parent's terms as the scorer crops them: a strided window of a larger block.
        block = rng.normal(size=(rows + 5, cols + 7, 2)).astype("f4")
        old = block[2 : 2 + rows, 3 : 3 + cols] if rng.random() < 0.7 else None
        got, want = fast.change(new, old), twin.change(new, old)
        assert isinstance(got, tuple) and len(got) == 2
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-9)


def test_change_hands_back_what_it_does_not_take():
    new = np.ones((3, 4, 2), "f4")
    assert kernels.compiled.change(new.astype("f8"), None) is None
    assert kernels.compiled.change(new, np.ones((3, 5, 2), "f4")) is None
    assert _Sums(kernels.compiled).change(new.astype("f8"), None) == (12.0, 12.0)
