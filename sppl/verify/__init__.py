"""Verified inference: does the sampler derived from a model leave its posterior invariant?

A sampler that is subtly wrong gives confident, wrong answers that look like right ones. These
checks catch it, on the shipped models in the test suite and on a user's own model through
``sppl verify model.scn`` (``verify_model``, in ``suite``):

- ``prior_declarations`` (``prior``): each prior draws what its density scores (births propose from one
  and the ratios assume the other), by the probability integral transform.
- ``prior_recovery`` (``prior``): with no observations the chain targets the prior, which is known exactly.
  Its per-class counts must be Poisson(lambda_c) (chi-square, tail bins pooled so that every
  expected count is at least 5), every parameter's marginal its prior (Kolmogorov-Smirnov for
  continuous parameters, chi-square for discrete ones), and under ``constraint no_overlap``
  (or bounded counts, or dependent priors) both must match independent samples from the prior
  (two-sample tests; rejection sampling where constrained).
- ``geweke`` (``joint``): Geweke's (2004) joint-distribution test with the renderer and the likelihoods in
  the loop, on tiny images. The marginal-conditional simulator draws scenes from the prior;
  the successive-conditional one alternates a sweep of the sampler given simulated
  observations with fresh observations simulated from the new state. If the sampler is right,
  both have the prior as their marginal over scenes.
- ``move_checks`` (``reverses``): every move and its reverse (``sppl.infer.jumps.reverse``): applying a proposal
  and then its reverse gives back the same trace, and the two log acceptance ratios are
  negatives of each other.
- ``sbc`` (``calibration``): simulation-based calibration: the rank of a true value among posterior draws is
  uniform.

The checks of the proposals that look at the observations are in ``proposals`` and
``exact_posterior``; what the checks run on (tiny cameras, simulated observations) in
``simulated``; their statistics in ``statistics``; reports in ``report``.

Statistics. MCMC draws are autocorrelated, and a test that treats them as independent raises
false alarms. The prior-recovery chain thins each quantity's draws to one every 3 tau sweeps,
tau being that quantity's integrated autocorrelation time (Geyer's initial monotone sequence
estimate), and tests a quantity only when the run is at least 200 tau long. The Geweke test
avoids the question: it runs many short independent chains, each started from an exact draw
of the joint distribution, so every chain is stationary from its first step if the sampler is
right, and compares their final states, which are independent, with independent prior draws.
SBC runs each replicate's chain forwards and (with the time-reversed sweep) backwards from the
true state, which makes the ranks exactly uniform at any chain length.

Every statistical row has a p-value; a ``Report`` decides pass or fail for all of them
together with Holm's step-down correction, so that the chance of *any* false alarm in a whole
report is at most ``alpha`` (default 0.01). Rows without a p-value are exact checks.
"""

from .calibration import sbc
from .exact_posterior import GridPosterior, joint_check, joint_ready
from .joint import geweke
from .prior import prior_declarations, prior_recovery
from .proposals import check_proposals, observed_state
from .report import ALPHA, Report, Row, combine
from .reverses import change_declarations, check_reverse, move_checks, same_trace
from .simulated import (
                        Simulator,
                        for_checks,
                        prior_scene,
                        verify_cameras,
                        with_jumps,
                        with_prior_noise_steps,
)
from .statistics import chisquare_gof, chisquare_two_sample, integrated_time, poisson_gof
from .suite import verify_model

__all__ = [
    "ALPHA",
    "GridPosterior",
    "Report",
    "Row",
    "Simulator",
    "change_declarations",
    "check_proposals",
    "check_reverse",
    "chisquare_gof",
    "chisquare_two_sample",
    "combine",
    "for_checks",
    "geweke",
    "integrated_time",
    "joint_check",
    "joint_ready",
    "move_checks",
    "observed_state",
    "poisson_gof",
    "prior_declarations",
    "prior_recovery",
    "prior_scene",
    "same_trace",
    "sbc",
    "verify_cameras",
    "verify_model",
    "with_jumps",
    "with_prior_noise_steps",
]
