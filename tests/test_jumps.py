"""The jump registry (sppl/model/jumps.py, sppl/infer/jumps.py): the sampler looks each jump up
by name, and the chains it draws are the ones it drew when the jumps were an if-chain."""

from __future__ import annotations

import dataclasses
import importlib.util
import json
import re
import sys
from pathlib import Path

import numpy as np
import pytest
from false_alarms import EACH
from test_verify import seen_world
from toys import ball_class, block_class, toy_model

from sppl import (
    InferenceSettings,
    Jump,
    ModelError,
    PriorScorer,
    Sampler,
    SpplError,
    compile_model,
    jump_names,
    register_jump,
    unregister_jump,
)
from sppl.model.jumps import jump, reverse_pairs
from sppl.verify.simulated import Simulator, verify_cameras

ALL = {"birth": 1.0, "death": 1.0, "change": 1.0, "replace": 1.0, "refit": 1.0, "merge": 1.0,
       "split": 1.0, "fitted_birth": 1.0, "fitted_death": 1.0}


def weighted(model, tries=1):
    placed = tuple(dataclasses.replace(c, position=("x", "y")) for c in model.classes)
    return dataclasses.replace(model, classes=placed, inference=dataclasses.replace(
        model.inference, jump_weights=ALL, tries=tries))


def fingerprint(sampler, trace) -> tuple:
    objects = tuple((o.cls.name, tuple(sorted((k, _digits(v)) for k, v in o.values.items())))
                    for o in trace.objects)
    return objects, _digits(trace.score), _digits(sampler.rng.random()), sorted(
        (k, tuple(v)) for k, v in sampler.stats.counts.items())


def _digits(v) -> str:
    """A value as recorded: a number to 12 significant digits. A chain drawn in the same
    order ends the same on every machine but for the last bit or two of its arithmetic
    (numpy's vector instructions differ between processors: one machine's block ended
    0.4103025450436564 m from the origin, another's 0.41030254504365615)."""
    return f"{float(v):.12g}" if isinstance(v, (float, np.floating)) else repr(v)


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
# another order, or proposes anything else, shows here. The observed chains were recorded
# again when the data-driven birth's thresholds changed (sppl/infer/birth.py): their births
# use them; and all but prior1 when the fit started from the best of several prior draws and
# tried an angle's turns (sppl/infer/fit.py): their refits, merges and fitted births use it;
# and all four when a merge could take up to twelve objects, fewer more often
# (sppl/infer/merge.py); and the two prior chains when a merge partner's colour counted
# (sppl/infer/merge.py: the toy ball is red and the block blue); and the two observed chains
# when a fitted birth chose its class by the fits (sppl/infer/fitted_birth.py), and all four
# when a merged object did (sppl/infer/merge.py), and again when a refitted one did
# (sppl/infer/fit.py); and observed3 when a fitted birth's fit also searched with the place
# held at its seed (sppl/infer/fit.py); and the two observed chains when depth specks seeded
# and fits at a speck's seed shrank their starts (sppl/infer/birth.py, sppl/infer/fit.py);
# and observed3 when a fit of another class also started from draws sized to the object it
# replaces (sppl/infer/fit.py).
RECORDED = Path(__file__).parent / "fixtures" / "jump_chains.json"
CHAINS = {"prior1": lambda: prior_chain(1), "prior3": lambda: prior_chain(3),
          "observed1": lambda: observed_chain(1), "observed3": lambda: observed_chain(3)}


@pytest.mark.parametrize("name", sorted(CHAINS))
def test_the_chains_are_the_ones_drawn_before_the_registry(name, request):
    if name.startswith("observed"):
        request.getfixturevalue("require_gl")
    assert repr(CHAINS[name]()) == json.loads(RECORDED.read_text())[name]


# -- the registry ---------------------------------------------------------------------------


def test_the_built_in_jumps_and_their_reverses():
    """The names, their order (which the chains' draws depend on), the pairs the language
    checks, and the default weights are the ones the if-chain, ``moves.JUMPS``, compile's
    ``_REVERSE_JUMPS`` and ``InferenceSettings`` listed."""
    assert jump_names() == ("birth", "death", "change", "replace", "refit", "merge", "split",
                            "fitted_birth", "fitted_death", "fitted_split", "fitted_merge",
                            "pair_refit")
    assert reverse_pairs() == (("birth", "death"), ("merge", "split"),
                               ("fitted_birth", "fitted_death"),
                               ("fitted_split", "fitted_merge"))
    assert InferenceSettings().jump_weights == {
        "birth": 1.0, "death": 1.0, "change": 1.0, "replace": 1.0, "refit": 0.0, "merge": 0.0,
        "split": 0.0, "fitted_birth": 0.0, "fitted_death": 0.0, "fitted_split": 0.0,
        "fitted_merge": 0.0, "pair_refit": 0.0}
    for name in jump_names():
        assert jump(jump(name).reverse).reverse == name


def _nothing(sampler, trace, rng):
    return None


def test_registration_needs_a_reverse_that_declares_the_jump_back():
    with pytest.raises(SpplError, match="'grow' declares 'shrink' as its reverse, which is not"):
        register_jump(Jump("grow", _nothing, "shrink", _nothing))
    with pytest.raises(SpplError, match="'grow' declares 'birth' as its reverse, but 'birth' "
                                        "declares 'death'"):
        register_jump(Jump("grow", _nothing, "birth", _nothing))
    with pytest.raises(SpplError, match="'birth' is registered twice"):
        register_jump(Jump("birth", _nothing, "birth", _nothing))
    with pytest.raises(SpplError, match="remove the two together"):
        unregister_jump("merge")
    assert "grow" not in jump_names()
    register_jump(Jump("grow", _nothing, "shrink", _nothing),
                  Jump("shrink", _nothing, "grow", _nothing))
    try:
        assert jump_names()[-2:] == ("grow", "shrink")
        assert reverse_pairs()[-1] == ("grow", "shrink")
    finally:
        unregister_jump("grow", "shrink")
    assert "grow" not in jump_names()


# -- the walkthrough: docs/walkthroughs/adding-a-jump.md --------------------------------------

ROOT = Path(__file__).resolve().parent.parent
EXAMPLE = ROOT / "examples" / "jumps" / "rescale.py"
WALKTHROUGH = ROOT / "docs" / "walkthroughs" / "adding-a-jump.md"


def rescale_module():
    spec = importlib.util.spec_from_file_location("rescale_example", EXAMPLE)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture
def rescale(monkeypatch):
    """The example's module, importable as ``rescale`` as the walkthrough imports it; the
    jump is removed after the test, whatever it registered."""
    module = rescale_module()
    monkeypatch.setitem(sys.modules, "rescale", module)
    yield module
    if module.NAME in jump_names():
        unregister_jump(module.NAME)


def python_blocks() -> list[str]:
    return re.findall(r"```python\n(.*?)```", WALKTHROUGH.read_text(), re.DOTALL)


def test_the_walkthrough_quotes_the_example_as_it_is():
    source = EXAMPLE.read_text()
    quoted = [b for b in python_blocks() if not b.startswith("# example")]
    assert len(quoted) == 4
    for block in quoted:
        assert block in source, block


@pytest.mark.false_alarm(EACH)
def test_the_walkthrough_runs(rescale):
    """The walkthrough's own block: the rescale jump passes the move checks (exact) and prior
    recovery (at alpha 1e-4, which is EACH), and without its Jacobian fails both (the rescale
    that forgets it drifts to an exponential: p about 1e-32 at this seed)."""
    assert EACH == 1e-4
    (block,) = [b for b in python_blocks() if b.startswith("# example")]
    exec(compile(block, str(WALKTHROUGH), "exec"), {})  # noqa: S102  (the doc's own code)
    assert rescale.NAME not in jump_names()


def test_a_model_file_weighs_a_jump_once_it_is_registered(rescale):
    text = ("class ball {{ count ~ poisson(1)\n    x : real ~ normal(0, 1)\n"
            "    geometry sphere(0.2) at (x, 0) colour rgb(1, 0, 0) }}\n"
            "inference {{ jump_weights {} }}\n")
    with pytest.raises(ModelError, match="unknown jump `rescale`"):
        compile_model(text.format("rescale = 1"))
    register_jump(rescale.RESCALE)
    model = compile_model(text.format("rescale = 2"))
    assert model.inference.jump_weights["rescale"] == 2.0
    assert model.inference.jump_weights["birth"] == 1.0
    assert InferenceSettings().jump_weights["rescale"] == 0.0
    sampler = Sampler(model, PriorScorer(), np.random.default_rng(0))
    assert sampler.jump["rescale"] == pytest.approx(2 / 5)  # birth, death, replace 1 each
    trace = sampler.initial_trace()
    assert trace.objects == ()
    assert jump("rescale").propose(sampler, trace, sampler.rng) is None
    # Where the jump is not registered (another process), the compiled model is refused
    # rather than run with the jump's weight counting for nothing.
    unregister_jump(rescale.NAME)
    with pytest.raises(SpplError, match="weighs the jump rescale, not registered"):
        Sampler(model, PriorScorer(), np.random.default_rng(0))


def test_an_installed_package_offers_jumps_through_the_entry_point_group(rescale, monkeypatch):
    """A pair from an entry point is registered when the registry is first read, in any
    process, so a worker that never imported the package knows the jump too."""
    from sppl.model import jumps as registry

    grow = Jump("grow", _nothing, "shrink", _nothing)
    shrink = Jump("shrink", _nothing, "grow", _nothing)

    class EntryPoint:
        def __init__(self, name, loaded):
            self.name, self.value, self.loaded = name, f"pkg:{name}", loaded

        def load(self):
            if isinstance(self.loaded, Exception):
                raise self.loaded
            return self.loaded

    found = [EntryPoint("rescale", rescale.RESCALE), EntryPoint("grow", (grow, shrink))]
    monkeypatch.setattr(registry, "entry_points", lambda group: found if group == "sppl.jumps"
                        else [])
    monkeypatch.setattr(registry, "_plugins_loaded", False)
    try:
        names = jump_names()
        assert names[-3:] == ("rescale", "grow", "shrink")
        assert ("grow", "shrink") in reverse_pairs()
    finally:
        unregister_jump("grow", "shrink")
    monkeypatch.setattr(registry, "_plugins_loaded", False)
    found[:] = [EntryPoint("broken", ImportError("no module named pkg"))]
    with pytest.raises(SpplError, match="the jump plugin 'broken' .* failed to load"):
        jump_names()
