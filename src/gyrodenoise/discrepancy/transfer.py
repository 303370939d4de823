"""Do a named effect's sensor constants agree between the fit and the held-out sequences? Standard errors scaled
by the disagreement.

The regression's standard errors assume the residual's fitted noise model. On independent test data
(`benchmarks/discrepancy_se_calibration.py`) they were 1.0-1.5 times too small on replayed flights and up to ~2
times on fast motion with a noisy sensor: the estimate moves with the motion by more than the noise says.
The held-out sequences see the same sensor under other motion, so refitting the selected model there gives a
second estimate of each constant. Their difference against the two covariances gives a chi-square, and the Birge
ratio R = sqrt(chi2 / dof); where R > 1 the standard errors are multiplied by R (never shrunk).
"""

from __future__ import annotations

import numpy as np
from scipy import stats

from gyrodenoise.discrepancy.design import Design, FitResult, sensor_view
from gyrodenoise.discrepancy.fitted_model import Selection
from gyrodenoise.sim.context import FitContext


def _block(res: FitResult, cols: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Coefficients and covariance of global columns `cols` in fit `res`."""
    pos = {int(g): i for i, g in enumerate(res.idx)}
    p = np.array([pos[int(c)] for c in np.ravel(cols)])
    return res.coef[np.ravel(cols)], res.cov[np.ix_(p, p)]


def transfer_check(sel: Selection, holdout: list[FitContext]) -> dict[str, dict]:
    """Per named sensor constant (regression effects the sequences share): the held-out refit's chi-square
    against the fit's estimate, its p-value, the Birge ratio and the factor applied to the standard errors."""
    regress = [n for n in sel.selected if not sel.effects[n].stochastic]
    shared = [n for n in sel.named if n in regress and not sel.effects[n].per_sequence]
    if not shared or not holdout or sel.design is None:
        return {}
    view = [sensor_view(fc, sel.corner_hz) for fc in holdout]
    design = Design(view, {n: sel.effects[n] for n in regress}, sel.sigma)
    res = design.fit(regress)
    out = {}
    for name in shared:
        others = [n for n in regress if n != name]
        if not np.all(np.isfinite(design.conditional_se(others, name, 1.0))):
            out[name] = {"separable_on_held_out": False, "se_factor": 1.0}
            continue
        c_fit, v_fit = _block(sel.result, sel.design.cols[name])
        c_hold, v_hold = _block(res, design.cols[name])
        d = c_fit - c_hold
        chi2 = float(d @ np.linalg.pinv(v_fit + v_hold, hermitian=True) @ d)
        dof = len(d)
        ratio = float(np.sqrt(chi2 / dof))
        out[name] = {
            "separable_on_held_out": True,
            "chi2": chi2,
            "dof": dof,
            "p_value": float(stats.chi2.sf(chi2, dof)),
            "birge_ratio": ratio,
            "se_factor": max(1.0, ratio),
        }
    return out


def apply_transfer_check(sel: Selection, holdout: list[FitContext]) -> None:
    """Record `transfer_check` on the selection and scale the named constants' standard errors by it."""
    sel.transfer = transfer_check(sel, holdout)
    for name, t in sel.transfer.items():
        sel.se[name] = {k: np.asarray(v) * t["se_factor"] for k, v in sel.se.get(name, {}).items()}
