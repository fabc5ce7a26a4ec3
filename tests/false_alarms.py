"""The test suite's false-alarm budget: how often a correct sppl fails a statistical test.

A statistical test at a fixed seed is deterministic, but its seed is one draw: reseeded, a
test at rate a fails a correct program with probability a. About fifty such tests at 1% each
would fail a reseeded suite by chance about four times in ten. So the default suite has one
budget, BUDGET = 1% in all (family-wise), and the slow tests one of their own, SLOW_BUDGET = 1%:
by the union (Bonferroni) bound, a correct program fails a suite by chance at most that often,
however the tests depend on one another.

Each budget is split into equal shares: the default suite's into SLOTS = 100 of EACH = 1e-4
(room for 100 statistical tests; about 60 use one now), the slow tests' into SLOW_SLOTS = 25 of
SLOW_EACH = 4e-4. A statistical test carries its rate beside it, ``@pytest.mark.false_alarm(
EACH)``, and gets it from the ``false_alarm`` fixture to decide with: as the alpha of a
``verify`` report (Holm's correction inside the report keeps the report's family-wise rate at
it), or as the threshold of a p-value. A test whose tolerance was set another way carries the
rate derived from that tolerance (written beside it), smaller than a share. Each parametrised
case is one test and takes its own share.

``tests/test_false_alarms.py`` collects the whole suite and checks that the rates of the default
tests add up to at most BUDGET and those of the slow tests to at most SLOW_BUDGET, and that
every test that computes a p-value or decides a statistical report carries a rate or is named
in NOT_FALSE_ALARMS with the reason. The list of tests and their rates:
``python -m pytest --collect-only -q -m false_alarm -n 0`` (with ``-m "false_alarm and slow"``
for the slow ones); ``docs/inference.md`` ("The false-alarm budget") says the same.
"""

from __future__ import annotations

import math

BUDGET = 0.01
SLOTS = 100
EACH = BUDGET / SLOTS

SLOW_BUDGET = 0.01
SLOW_SLOTS = 25
SLOW_EACH = SLOW_BUDGET / SLOW_SLOTS

# Tests that compute p-values or statistical reports but whose failure is not a false alarm:
# they assert that a check *rejects* a broken sampler (a miss is their failure, and its chance
# is the check's power at the rate it runs at, shown by the test passing at its fixed seed), or
# they look at something else than the verdict.
NOT_FALSE_ALARMS = {
    "test_prior_recovery_sees_a_change_without_its_jacobian": "asserts a rejection",
    "test_prior_recovery_sees_a_newborn_taken_for_free": "asserts a rejection",
    "test_the_exact_posterior_sees_a_fitted_density_left_out": "asserts a rejection",
    "test_the_exact_posterior_sees_a_newborn_taken_for_free": "asserts a rejection",
    "test_a_swap_with_its_ratio_reversed_is_caught": "asserts a rejection",
    "test_prior_recovery_sees_a_refit_taken_for_symmetric": "asserts a rejection",
    "test_prior_recovery_sees_a_pair_refit_taken_for_symmetric": "asserts a rejection",
    "test_prior_recovery_sees_a_side_kept_by_the_step_sign": "asserts a rejection",
    "test_a_class_choice_left_out_of_the_ratio_is_caught": "asserts a rejection",
    "test_prior_recovery_sees_a_multiple_try_birth_without_its_mean": "asserts a rejection",
    "test_geweke_sees_a_simulator_that_leaves_out_the_static_scenery": "asserts a rejection",
    "test_geweke_rejects_a_likelihood_whose_sampler_disagrees": "asserts a rejection",
    "test_sppl_verify_names_the_failing_check_of_a_broken_likelihood": "asserts a rejection",
    "test_sppl_verify_names_a_dependent_prior_that_leaves_its_domain":
        "an error of the model, not a p-value, fails it",
    "test_sppl_verify_names_a_change_that_cannot_carry_a_parameter_back":
        "the compiler's error, not a p-value, fails it",
    "test_geweke_and_sbc_start_from_scenes_in_random_order":
        "runs the checks for their starting scenes, not their verdicts",
    "test_an_untested_row_is_shown_as_untested_and_fails_only_under_strict":
        "a report made by hand: no test is run",
    "test_sppl_verify_strict_exits_1_on_an_untested_row": "a report made by hand",
    "test_the_thesis_ratio_still_passes_the_reverse_check": "exact move checks only",
    "test_every_move_and_its_reverse": "exact move checks only",
    "test_moves_and_reverses_with_data_driven_births": "exact move checks only",
    "test_every_merge_and_split_and_its_reverse": "exact move checks only",
    "test_every_refit_and_its_reverse": "exact move checks only",
    "test_every_multiple_try_jump_and_its_reverse": "exact move checks only",
    "test_a_jump_without_a_known_reverse_fails_the_move_checks": "exact move checks only",
    "test_a_broken_reverse_is_caught": "exact move checks only",
    "test_a_replace_without_its_proposal_ratio_is_caught": "exact move checks only",
    "test_a_change_that_cannot_carry_a_parameter_back_is_named": "exact move checks only",
    "test_a_lighting_move_with_a_wrong_ratio_is_caught": "asserts a rejection",
    "test_sppl_verify_catches_a_misnormalised_mixture": "asserts a rejection",
    "test_sppl_verify_reports_a_bad_region_in_one_line":
        "the compiler's error, not a p-value, fails it",
}


def two_proportions_p(k1: int, n1: int, k2: int, n2: int) -> float:
    """Two-sided p-value of k1/n1 = k2/n2 (the pooled z-test; n in the thousands here)."""
    from scipy import stats

    pooled = (k1 + k2) / (n1 + n2)
    se = math.sqrt(pooled * (1 - pooled) * (1 / n1 + 1 / n2))
    if se == 0.0:
        return 1.0 if k1 / n1 == k2 / n2 else 0.0
    return float(2 * stats.norm.sf(abs(k1 / n1 - k2 / n2) / se))
