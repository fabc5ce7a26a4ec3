"""The jump registry (sppl/model/jumps.py, sppl/infer/jumps.py): the sampler looks each jump up
by name, and the chains it draws are the ones it drew when the jumps were an if-chain."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
from test_verify import seen_world
from toys import ball_class, block_class, toy_model

from sppl import PriorScorer, Sampler
from sppl.verify.simulated import Simulator, verify_cameras

ALL = {"birth": 1.0, "death": 1.0, "change": 1.0, "replace": 1.0, "refit": 1.0, "merge": 1.0,
       "split": 1.0, "fitted_birth": 1.0, "fitted_death": 1.0}


def weighted(model, tries=1):
    placed = tuple(dataclasses.replace(c, position=("x", "y")) for c in model.classes)
    return dataclasses.replace(model, classes=placed, inference=dataclasses.replace(
        model.inference, jump_weights=ALL, tries=tries))


def fingerprint(sampler, trace) -> tuple:
    objects = tuple((o.cls.name, tuple(sorted((k, repr(v)) for k, v in o.values.items())))
                    for o in trace.objects)
    return objects, repr(trace.score), repr(sampler.rng.random()), sorted(
        (k, tuple(v)) for k, v in sampler.stats.counts.items())


def prior_chain(tries: int, sweeps: int = 300):
    model = weighted(toy_model([ball_class(rate=2.0), block_class(rate=1.0)]), tries)
    sampler = Sampler(model, PriorScorer(), np.random.default_rng(11))
    trace = sampler.initial_trace()
    for _ in range(sweeps):
        trace = sampler.sweep(trace)
    return fingerprint(sampler, trace)


def observed_chain(tries: int, sweeps: int = 60, seed: int = 1):
    from sppl.model.simulate import sample_noise, sample_objects
    from sppl.render import Renderer

    model = weighted(seen_world(), tries)
    rng = np.random.default_rng(seed)
    sim = Simulator(model, verify_cameras(model, 16), Renderer(model.render))
    objs, noise = sample_objects(model, rng), sample_noise(model, rng)
    sampler = sim.sampler(sim.observe(sim.render(objs, noise), noise, rng), rng, Sampler)
    trace = sampler.initial_trace()
    for _ in range(sweeps):
        trace = sampler.sweep(trace)
    return fingerprint(sampler, trace)


# What each chain ended with (objects, score, the generator's next draw, the acceptance counts)
# when the jumps were dispatched by an if-chain, before the registry: a change that draws in
# another order, or proposes anything else, shows here.
RECORDED = Path(__file__).parent / "fixtures" / "jump_chains.json"
CHAINS = {"prior1": lambda: prior_chain(1), "prior3": lambda: prior_chain(3),
          "observed1": lambda: observed_chain(1), "observed3": lambda: observed_chain(3)}


@pytest.mark.parametrize("name", sorted(CHAINS))
def test_the_chains_are_the_ones_drawn_before_the_registry(name, request):
    if name.startswith("observed"):
        request.getfixturevalue("require_gl")
    assert repr(CHAINS[name]()) == json.loads(RECORDED.read_text())[name]
