"""Comparing an estimated scene with the true one: matching objects and measuring errors."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.optimize import linear_sum_assignment

Obj = Mapping[str, Any]  # {"class": name, "params": {...}}

# How far (ground-plane metres) a matched object may be from the true one for a scene to count as
# recovered: the benchmarks', the data-set summary's and the report's criterion.
TOLERANCE = 0.15


@dataclass(frozen=True)
class SceneErrors:
    n_true: int
    n_estimated: int
    wrong_class: int  # matched pairs whose class differs
    wrong_category: int  # matched pairs whose categorical parameters (colours) differ
    position_errors: tuple[float, ...]  # ground-plane distance of each matched pair, metres

    @property
    def max_position_error(self) -> float:
        return max(self.position_errors, default=0.0)

    def correct(self, tolerance: float = TOLERANCE) -> bool:
        """Right count, classes and colours, and every position within ``tolerance`` metres."""
        return (
            self.n_true == self.n_estimated
            and self.wrong_class == 0
            and self.wrong_category == 0
            and self.max_position_error <= tolerance
        )


def _xy(o: Obj) -> np.ndarray:
    return np.array([float(o["params"].get("x", 0.0)), float(o["params"].get("y", 0.0))])


def compare_scenes(estimate: Sequence[Obj], truth: Sequence[Obj]) -> SceneErrors:
    """Match estimated to true objects by ground-plane position (optimal assignment), then
    count class and category mismatches among the matched pairs."""
    if not estimate or not truth:
        return SceneErrors(len(truth), len(estimate), 0, 0, ())
    cost = np.array([[np.linalg.norm(_xy(e) - _xy(t)) for t in truth] for e in estimate])
    rows, cols = linear_sum_assignment(cost)
    wrong_class = wrong_cat = 0
    for r, c in zip(rows, cols):
        e, t = estimate[r], truth[c]
        if e["class"] != t["class"]:
            wrong_class += 1
        cats = {k: v for k, v in t["params"].items() if isinstance(v, str)}
        if any(e["params"].get(k) != v for k, v in cats.items()):
            wrong_cat += 1
    return SceneErrors(
        len(truth), len(estimate), wrong_class, wrong_cat, tuple(float(cost[r, c]) for r, c in zip(rows, cols))
    )


def match_objects(
    estimate: Sequence[Obj], truth: Sequence[Obj], max_distance: float = math.inf
) -> list[tuple[int, int, float]]:
    """Pairs (estimate index, truth index, ground-plane distance) of the optimal assignment by
    position, as ``compare_scenes`` matches them, leaving out pairs farther apart than
    ``max_distance`` metres."""
    if not estimate or not truth:
        return []
    cost = np.array([[np.linalg.norm(_xy(e) - _xy(t)) for t in truth] for e in estimate])
    rows, cols = linear_sum_assignment(cost)
    return [(int(r), int(c), float(cost[r, c]))
            for r, c in zip(rows, cols) if cost[r, c] <= max_distance]
