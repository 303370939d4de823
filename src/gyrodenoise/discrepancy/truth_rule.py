"""The ground-truth rule: what the discrepancy workflow may decide when a truth follows the gyro.

A residual gyro - truth against a truth that carries the gyro (`truth_check`) is the fusion's error, not the
sensor's. Effects judged against such a truth on a fit sequence cannot be named; their transfer cannot be judged
on such a held-out sequence, which is set aside while another is left. Effects read off the gyro's own values
(`truth_check.TRUTH_FREE`) are unaffected.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TypeVar

from gyrodenoise.discrepancy.truth_check import TRUTH_FREE, followed_in_band
from gyrodenoise.discrepancy.workflow import verdict_text
from gyrodenoise.sim.context import FitContext
from gyrodenoise.sim.effects import EFFECTS

T = TypeVar("T")


@dataclass
class TruthRule:
    """What the ground-truth check (`truth_check`) lets the workflow decide. A residual against a truth that
    carries the gyro is the fusion's error, not the sensor's: effects judged against such a truth on a fit
    sequence cannot be named, and their transfer cannot be judged on such a held-out sequence."""

    fit_followed: dict[str, list[list[float]]]  # fit sequences whose truth follows the gyro in their compared band
    holdout_followed: dict[str, list[list[float]]]  # the same among the held-out sequences
    holdout_kept: list[str]  # held-out sequences the practical minimum and the gaps use

    @property
    def decided(self) -> bool:
        """Effects judged against the truth can be decided: no fit truth follows the gyro and at least one
        held-out truth does not (the rest are set aside)."""
        return not self.fit_followed and self.judges_holdout

    @property
    def judges_holdout(self) -> bool:
        """A held-out sequence the gaps use has a truth that does not follow the gyro (the residual there is the
        sensor's)."""
        return any(n not in self.holdout_followed for n in self.holdout_kept)

    def withheld(self, named: list[str]) -> list[str]:
        """The named effects that were judged against the truth (all but those named from the gyro alone)
        when the truth cannot decide them."""
        return [] if self.decided else [n for n in named if n not in TRUTH_FREE]

    def note(self) -> str:
        """What the verdict must add ('' when nothing was followed)."""
        aside = [n for n in self.holdout_followed if n not in self.holdout_kept]
        where = [", ".join(self.fit_followed)] if self.fit_followed else []
        if self.holdout_followed and not aside:
            where.append(f"every held-out sequence ({', '.join(self.holdout_followed)})")
        parts = []
        if where:
            on = " and on ".join(where)
            parts.append(f"effects judged against the ground truth: not decided (it follows the gyro on {on})")
        if aside:
            parts.append(f"held-out {', '.join(aside)} set aside (its ground truth follows the gyro)")
        return "; ".join(parts)

    def kept(self, holdout: list[FitContext]) -> list[FitContext]:
        """The held-out contexts the practical minimum and the gaps use (`holdout_kept`, per recording)."""
        return [fc for fc in holdout if sequence_of(fc) in self.holdout_kept]

    def summary(self, withheld: list[str]) -> dict:
        return {
            "fit_sequences": self.fit_followed,
            "holdout_sequences": self.holdout_followed,
            "holdout_used": self.holdout_kept,
            "decided": self.decided,
            "withheld": withheld,
        }


def sequence_of(fc: FitContext) -> str:
    """The recording a context comes from (a stretch between ground-truth gaps carries its recording's name)."""
    return fc.extra.get("sequence", fc.name)


def truth_rule(fit: list[FitContext], holdout: list[FitContext], truth_checks: dict[str, dict] | None) -> TruthRule:
    """The sequences whose ground truth follows the gyro inside their compared band (`truth_check`; the bands are
    those the selection estimated, so call it after one), and the held-out sequences left to judge transfer on:
    the others, or all of them when every held-out truth follows the gyro (the gaps are still shown). Checks and
    results are per recording (`sequence_of`), not per stretch."""
    checks = truth_checks or {}
    f_max: dict[str, float] = {}
    for fc in [*fit, *holdout]:
        if "band" in fc.extra:  # a recording's widest compared band over its stretches
            f_max[sequence_of(fc)] = max(f_max.get(sequence_of(fc), 0.0), fc.extra["band"].f_max_hz)

    def followed(fcs: list[FitContext]) -> dict[str, list[list[float]]]:
        names = dict.fromkeys(sequence_of(fc) for fc in fcs)
        return followed_in_band({n: checks[n] for n in names if n in checks}, f_max)

    fit_f, hold_f = followed(fit), followed(holdout)
    hold_names = list(dict.fromkeys(sequence_of(fc) for fc in holdout))
    kept = [n for n in hold_names if n not in hold_f] or hold_names
    return TruthRule(fit_f, hold_f, kept)


def with_truth_rule(
    select: Callable[[list[FitContext], list[str] | None], tuple[T, list[str]]],
    fit: list[FitContext],
    holdout: list[FitContext],
    truth_checks: dict[str, dict] | None,
    base: list[str],
    candidates: list[str] | None,
) -> tuple[T, TruthRule, list[str]]:
    """Run `select(held-out sequences, candidates) -> (result, named effects)`, then apply the ground-truth rule:
    held-out sequences whose truth follows the gyro are set aside, and when the truth cannot decide (`TruthRule`)
    the effects named against it are withheld and the selection is redone with the truth-free candidates.
    Returns (result, rule, withheld effects)."""
    result, named = select(holdout, candidates)
    rule = truth_rule(fit, holdout, truth_checks)
    withheld = rule.withheld(named)
    kept = rule.kept(holdout)
    if withheld or len(kept) < len(holdout):
        result, _ = select(kept, truth_free_vocabulary(base, candidates) if withheld else candidates)
    return result, rule, withheld


def truth_free_vocabulary(base: list[str], candidates: list[str] | None) -> list[str]:
    """The candidates left when the truth cannot judge: those of `candidates` (None: all) named from the gyro alone."""
    return [c for c in (candidates if candidates is not None else EFFECTS) if c in TRUTH_FREE and c not in base]


def withhold_unexplained(report: dict, rule: TruthRule) -> None:
    """The lack-of-fit check (`lack_of_fit`) reads the held-out residual against the truth: where every held-out
    truth it used follows the gyro, what it finds is the fusion's error as much as the sensor's. Its caution then
    leaves the verdict; the table stays, marked not decided."""
    lof = report.get("lack_of_fit")
    if not lof or rule.judges_holdout:
        return
    lof["decided"] = False
    if lof["caution"]:
        report["cautions"] = [c for c in report["cautions"] if c != lof["caution"]]
        named = [e["name"] for e in report["named_effects"]]
        report["verdict"] = verdict_text(named, report["equivalences"], report["cautions"])
