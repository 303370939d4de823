"""Do a named effect's sensor constants agree between the fit and the held-out sequences? Standard errors scaled
by the disagreement.

The regression's standard errors assume the residual's fitted noise model. On independent test data
(`benchmarks/discrepancy_se_calibration.py`) they were 1.0-1.5 times too small on replayed flights and up to ~2
times on fast motion with a noisy sensor: the estimate moves with the motion by more than the noise says.
The held-out sequences see the same sensor under other motion, so refitting the selected model there gives a
second estimate of each constant. Their difference against the two covariances gives a chi-square, and the Birge
ratio R = sqrt(chi2 / dof); where R > 1 the standard errors are multiplied by R (never shrunk).

Whether the constant transferred is not read from that chi-square alone: against the regression's covariances it
called a g-sensitivity that was the same in every sequence "not transferred" (p < 0.01 in 5 of 12 test-world seeds,
R up to 2.2), because those covariances fall short by the same factor on every sequence. With two or more fit
sequences that separate the constant alone, the reference is their own spread (`replicates.among`): the held-out
estimate must differ from the fit's by more than the fit sequences differ among themselves, an F-test with both
chi-squares scaled by the same unknown factor (its estimate never below 1: the regression's covariance is the
least the sensor's noise gives). That spread is itself checked against the halves of every sequence
(`replicates.pure_error`, estimation error alone): a constant that differs between the fit sequences (each flight its
own value) shows there, where the held-out test, set against that spread, cannot see it.
"""

from __future__ import annotations

import numpy as np
from scipy import stats

from gyrodenoise.discrepancy.design import Design
from gyrodenoise.discrepancy.fitted_model import Selection
from gyrodenoise.discrepancy.replicates import among, block, chi2_of, replicates_of
from gyrodenoise.sim.context import FitContext


def _f_test(chi2: float, dof: int, ref: dict) -> float:
    """p of chi2 / dof against a reference chi-square's chi2 / dof (floored at 1), F(dof, ref dof)."""
    scale = max(1.0, ref["chi2"] / ref["dof"])
    return float(stats.f.sf(chi2 / dof / scale, dof, ref["dof"]))


def transfer_check(sel: Selection, holdout: list[FitContext]) -> dict[str, dict]:
    """Per named sensor constant (regression effects the sequences share): the held-out refit's chi-square
    against the fit's estimate, the Birge ratio and the factor applied to the standard errors, and the p-value of the
    transfer: against the fit sequences' own spread where two or more separate the constant (`fit_sequences`, with its
    own p against the sequences' halves), else against the regression's covariances (`p_value_regression_se`)."""
    regress = [n for n in sel.selected if not sel.effects[n].stochastic]
    shared = [n for n in sel.named if n in regress and not sel.effects[n].per_sequence]
    if not shared or not holdout or sel.design is None:
        return {}
    reps = replicates_of(sel, holdout)
    n_fit = len(sel.design.fcs)
    design = Design(reps.views[n_fit:], {n: sel.effects[n] for n in regress}, sel.sigma)  # the held-out together
    res = design.fit(regress)
    out = {}
    for name in shared:
        others = [n for n in regress if n != name]
        if not np.all(np.isfinite(design.conditional_se(others, name, 1.0))):
            out[name] = {"separable_on_held_out": False, "se_factor": 1.0}
            continue
        fitted, held = block(sel.result, sel.design.cols[name]), block(res, design.cols[name])
        chi2 = chi2_of(fitted, held)
        dof = len(fitted[0])
        ratio = float(np.sqrt(chi2 / dof))
        p_reg = float(stats.chi2.sf(chi2, dof))
        entry = {
            "separable_on_held_out": True,
            "chi2": chi2,
            "dof": dof,
            "p_value": p_reg,
            "p_value_regression_se": p_reg,
            "reference": "regression standard errors",
            "birge_ratio": ratio,
            "se_factor": max(1.0, ratio),
        }
        spread = among(reps.estimates(name, list(range(n_fit)))) if n_fit > 1 else None
        if spread is not None:
            entry |= {"p_value": _f_test(chi2, dof, spread), "reference": "fit sequences", "fit_sequences": spread}
            halves = reps.pure_error(name)
            if halves is not None:
                spread |= {"p_value": _f_test(spread["chi2"], spread["dof"], halves), "halves": halves}
        out[name] = entry
    return out


def apply_transfer_check(sel: Selection, holdout: list[FitContext]) -> None:
    """Record `transfer_check` on the selection and scale the named constants' standard errors by it."""
    sel.transfer = transfer_check(sel, holdout)
    for name, t in sel.transfer.items():
        sel.se[name] = {k: np.asarray(v) * t["se_factor"] for k, v in sel.se.get(name, {}).items()}
