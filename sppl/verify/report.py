"""A report of checks: its rows, and pass or fail for all of them together (Holm's correction)."""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np

ALPHA = 0.01


@dataclass(frozen=True)
class Row:
    """One line of a report. ``p_value`` is None for an exact (non-statistical) check, whose
    verdict is ``ok``; statistical rows are decided by their ``Report``."""

    check: str  # "prior", "geweke", "moves", "sbc"
    quantity: str
    expected: str
    observed: str
    p_value: float | None = None
    ok: bool = True
    # False for a row that could not be tested (a run too short for how slowly its quantity
    # mixes): it fails nothing, says nothing, and is shown as untested, never as a pass.
    tested: bool = True


@dataclass
class Report:
    rows: list[Row]
    alpha: float = ALPHA
    notes: list[str] = field(default_factory=list)

    @property
    def verdicts(self) -> list[bool]:
        """Pass (True) or fail per row, statistical rows by Holm's procedure at ``alpha``."""
        stat = [i for i, r in enumerate(self.rows) if r.p_value is not None]
        rejected = holm([self.rows[i].p_value for i in stat], self.alpha)
        out = [r.ok for r in self.rows]
        for i, rej in zip(stat, rejected):
            out[i] = not rej
        return out

    @property
    def passed(self) -> bool:
        return all(self.verdicts)

    @property
    def untested(self) -> list[str]:
        """The quantities a check left untested (a run too short for how slowly they mix):
        such a row fails nothing, but says nothing either (``strict`` fails on it)."""
        return [r.quantity for r in self.rows if not r.tested]

    @property
    def passed_strict(self) -> bool:
        """Every check passed and none was left untested (``sppl verify --strict``)."""
        return self.passed and not self.untested

    @property
    def failures(self) -> list[Row]:
        return [r for r, ok in zip(self.rows, self.verdicts) if not ok]

    def row(self, quantity: str, check: str | None = None) -> Row:
        for r in self.rows:
            if r.quantity == quantity and (check is None or r.check == check):
                return r
        raise KeyError(quantity)

    def table(self, strict: bool = False) -> str:
        """The report as a table and a verdict; with ``strict`` an untested row fails it."""
        head = ("check", "quantity", "expected", "observed", "p-value", "result")
        lines = [
            (r.check, r.quantity, r.expected, r.observed, format_p(r.p_value),
             "FAIL" if not ok else "untested" if not r.tested else "pass")
            for r, ok in zip(self.rows, self.verdicts)
        ]
        widths = [max(len(x[i]) for x in [head, *lines]) for i in range(len(head))]

        def fmt(cells) -> str:
            return "  ".join(
                c.rjust(w) if i == 4 else c.ljust(w) for i, (c, w) in enumerate(zip(cells, widths))
            ).rstrip()

        out = [fmt(head), fmt(tuple("-" * w for w in widths))]
        out += [fmt(x) for x in lines]
        n_stat = sum(r.p_value is not None for r in self.rows)
        untested = [f"{r.check}: {r.quantity}" for r in self.rows if not r.tested]
        out.append("")
        out.append(
            f"{n_stat} statistical checks, decided together by Holm's correction at a "
            f"family-wise false-alarm rate of {self.alpha:g}; "
            f"{len(self.rows) - n_stat - len(untested)} exact checks; "
            f"{len(untested)} untested."
        )
        out += self.notes
        if not self.passed:
            names = ", ".join(f"{r.check}: {r.quantity}" for r in self.failures)
            out.append(f"FAIL: {names}" + (f"; untested: {', '.join(untested)}" if untested
                                           else ""))
        elif untested and strict:
            out.append(f"FAIL (--strict): untested: {', '.join(untested)}")
        elif untested:
            out.append(f"PASS, but {len(untested)} untested (they say nothing either way; "
                       f"--strict fails on them): {', '.join(untested)}")
        else:
            out.append("PASS: every check passed.")
        return "\n".join(out)


def combine(reports: Iterable[Report], alpha: float = ALPHA) -> Report:
    rows, notes = [], []
    for r in reports:
        rows += r.rows
        notes += r.notes
    return Report(rows, alpha, notes)


def holm(p_values: Sequence[float], alpha: float) -> list[bool]:
    """Holm's step-down procedure: which hypotheses are rejected, with a family-wise error
    rate of at most ``alpha`` whatever the dependence between the tests."""
    m = len(p_values)
    rejected = [False] * m
    for i, j in enumerate(np.argsort(p_values, kind="stable")):
        if p_values[j] <= alpha / (m - i):
            rejected[j] = True
        else:
            break
    return rejected


def format_p(p: float | None) -> str:
    if p is None:
        return "-"
    if p < 1e-4:
        return f"{p:.1e}"
    return f"{p:.4f}"


# The moves without which a chain cannot reach every scene: against observations each of them
# must be accepted now and then. The other jumps only speed the chain up, and one fitted to
# the pixels (a merge, a split) can be rare against the observations of a prior scene.
NEEDED_MOVES = ("parameters", "noise", "birth", "death")


def acceptance_rows(check: str, by_move: dict[str, tuple[int, int]],
                     needed: tuple[str, ...] | None = None) -> tuple[list[Row], list[str]]:
    """Exact rows: every move type that was proposed was accepted at least once (a move that
    is never accepted leaves the target invariant, and the chain stuck). With ``needed``,
    only those moves must be; another that never was is reported in a note instead."""
    rows, notes = [], []
    for move, (n, a) in sorted(by_move.items()):
        if a == 0 and needed is not None and move not in needed:
            notes.append(f"{check}: no {move} move was accepted (0/{n}); it is not needed to "
                         "reach every scene, and prior recovery checks that it is accepted")
            continue
        rows.append(Row(check, f"{move} moves accepted", "some", f"{a}/{n} ({a / n:.0%})",
                        None, a > 0))
    return rows, notes
