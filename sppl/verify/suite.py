"""Every check of a model, as ``sppl verify`` runs them."""

from __future__ import annotations

from collections.abc import Callable

from ..errors import SpplError
from ..infer.chain import Sampler
from ..model.types import Model
from .joint import geweke
from .prior import prior_declarations, prior_recovery
from .report import ALPHA, Report, Row, combine
from .reverses import move_checks
from .simulated import for_checks
from .statistics import seed_sequence


def verify_model(
    model: Model,
    *,
    steps: int = 20_000,
    seed: int = 0,
    run_geweke: bool = True,
    geweke_chains: int = 100,
    geweke_length: int = 20,
    size: int = 8,
    alpha: float = ALPHA,
    renderer=None,
    sampler_factory: Callable[..., Sampler] = Sampler,
    progress: Callable[[str], None] | None = None,
    proposal_draws: int = 30,
) -> Report:
    """The check of the declarations, prior recovery, the move checks and (when the model has
    sensors) a short Geweke test and the checks of the proposals that look at the
    observations (``sppl.verify.proposals``, ``proposal_draws`` draws per transform; 0 leaves
    them out) on one model, in one report whose verdict is corrected for
    multiple comparisons. A check stopped by an error of the model (a dependent prior whose
    arguments break it for some values, say) gives a failing row with the error in the notes,
    and the others still run."""
    say = progress or (lambda message: None)
    prior_seq, moves_seq, geweke_seq, proposals_seq = seed_sequence(seed).spawn(4)
    model = for_checks(model)  # `region cameras`: the ground the verify cameras see
    if model.sensors and renderer is None and run_geweke:
        from ..render import Renderer

        renderer = Renderer(model.render)
    checks = [
        ("prior", "the priors' draws against their densities", None,
         lambda: prior_declarations(model, seed=prior_seq.spawn(1)[0])),
        ("prior", "prior recovery", f"prior recovery: {steps} sweeps with no observations ...",
         lambda: prior_recovery(model, sweeps=steps, seed=prior_seq,
                                sampler_factory=sampler_factory)),
        ("moves", "moves and their reverses", "moves and their reverses ...",
         lambda: move_checks(model, seed=moves_seq, size=size, renderer=renderer,
                             sampler_factory=sampler_factory, observe=run_geweke)),
    ]
    if run_geweke and model.sensors:
        checks.append((
            "geweke", "Geweke test",
            f"geweke: {geweke_chains} chains of {geweke_length} sweeps on {size}x{size} images ...",
            lambda: geweke(model, chains=geweke_chains, length=geweke_length, seed=geweke_seq,
                           size=size, renderer=renderer, sampler_factory=sampler_factory),
        ))
    if run_geweke and model.sensors and proposal_draws > 0:
        from .proposals import check_proposals

        checks.append((
            "proposals", "data-dependent proposals",
            (f"proposals: the data-dependent proposals' samplers against their densities, "
             f"{proposal_draws} draws each ..."),
            lambda: check_proposals(model, seed=proposals_seq, draws=proposal_draws,
                                    renderer=renderer, sampler_factory=sampler_factory),
        ))
    reports = []
    for check, what, message, run in checks:
        if message:
            say(message)
        try:
            reports.append(run())
        except SpplError as error:
            reports.append(Report(
                [Row(check, f"{what}: runs", "no error", "stopped by an error (below)", None,
                     False)],
                alpha, [f"{check}: {what} stopped: {error}"],
            ))
    return combine(reports, alpha)
