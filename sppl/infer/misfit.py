"""Which object of a state the observations disagree with: the refit jump's choice of object.

A cube the chain took for a cylinder stands in the right place with the right colour, and its
pixels differ from the observations only at the corners the cylinder rounds off. Every other
object of such a state is right, and a refit of one of them is a wasted move: with six
objects and the object chosen uniformly, the refit that would fix the cube comes once in
six. The refit instead chooses object k with probability

    q(k | x) = (1 - F) / n + F m_k(x) / sum_j m_j(x)

with m_k(x) the pixels of the state's renders, inside the rectangle object k covers in each
camera, that disagree with the observations (an RGB pixel by more than the birth's colour
gap, a depth pixel by more than its depth gap, either way), and q uniform where no pixel
disagrees or the scorer draws no rectangles (the reference and prior scorers). It is a
deterministic function of the state's renders, so a refit's ratio carries
q(k | y) / q(k | x), with y the state the refit proposes (the new object in k's place).
F is the model's ``refit_focus`` setting; at 0 (the default) the choice is uniform and draws
what it always drew. The uniform share keeps every object's chance at least (1 - F) / n, so
that refits of an object that looks right, which the chain also needs to mix, still come.
"""

from __future__ import annotations

import math

import numpy as np

from .birth import COLOUR_GAP, _measured


def disagreeing(sampler, trace) -> dict[str, np.ndarray]:
    """Per camera frame, the pixels where the state's renders and the observations disagree
    (an RGB term's and a depth term's together)."""
    birth = sampler.birth
    masks: dict[str, np.ndarray] = {}
    for t in birth.terms:
        rendered = birth.scorer.rendered(trace.renders, t)
        if t.kind == "image":
            off = np.abs(t.observed - rendered).mean(axis=-1) > COLOUR_GAP
        elif t.kind == "depth":
            off = np.abs(t.observed - rendered) > birth.depth_gaps[t.frame]
            off &= _measured(t.observed, t.valid, t.camera.depth_max)
        else:
            continue
        masks[t.frame] = masks[t.frame] | off if t.frame in masks else off
    return masks


def misfits(sampler, trace) -> np.ndarray | None:
    """m_k(x) per object of ``trace``: disagreeing pixels inside its rectangles; None where
    the scorer draws no rectangles or the state has no renders."""
    draws = getattr(sampler.scorer, "draws", None)
    frames = getattr(sampler.scorer, "frames", None)
    if draws is None or frames is None or trace.renders is None:
        return None
    cached = trace.cache.get("misfits")
    if cached is not None:
        return cached
    masks = disagreeing(sampler, trace)
    counts = np.zeros(len(trace.objects))
    for k, o in enumerate(trace.objects):
        for c, rect in enumerate(draws.of_object(o).rects):
            mask = masks.get(frames[c])
            if rect is not None and mask is not None:
                counts[k] += np.count_nonzero(mask[rect[0]:rect[1], rect[2]:rect[3]])
    trace.cache["misfits"] = counts
    return counts


def choice_log_probs(sampler, trace, focus: float | None = None) -> np.ndarray:
    """log q(k | trace) of the refit's choice of object, over the objects of ``trace``, with
    the model's focus or ``focus``."""
    n = len(trace.objects)
    focus = sampler.model.inference.refit_focus if focus is None else focus
    if n == 0:
        return np.empty(0)
    m = misfits(sampler, trace) if focus > 0.0 else None
    if m is None or m.sum() == 0:
        return np.full(n, -math.log(n))
    return np.log((1.0 - focus) / n + focus * m / m.sum())


def choose(sampler, trace, rng: np.random.Generator) -> int:
    """The refit's object, drawn from ``choice_log_probs``; without a focus, one integer from
    ``rng``, as the refit always drew it, so that a model without a focus keeps its chains."""
    if sampler.model.inference.refit_focus == 0.0:
        return int(rng.integers(len(trace.objects)))
    p = np.exp(choice_log_probs(sampler, trace))
    return int(rng.choice(len(p), p=p / p.sum()))
