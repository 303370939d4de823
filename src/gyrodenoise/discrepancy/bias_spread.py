"""The turn-on bias's spread between sequences, for the simulator (`sim_model`'s `bias_jitter_rad_s`).

Each sequence's bias is an estimate, so the spread of the estimates holds each one's own error beside the spread
of the turn-on bias itself. Their plain standard deviation (ddof 1) gave 2.6e-5 to 7.4e-5 rad/s (mean 5.3e-5, 12
runs of 3 x 60 s behind a Vicon-like mocap) on test-world flights whose turn-on bias was the same in every one, where
the regression's standard error of each was 2.3e-5. Method of moments instead, per axis: E sum_s (b_s - mean b)^2 =
(S - 1) tau^2 + tr(C V), with C the centring matrix and V the estimates' covariance from the fit (whole, not its
diagonal: the shared constants fitted beside the biases correlate them, a g-sensitivity's gravity column is nearly a
bias), scaled by the factor the sequences' halves show it falls short by (`replicates.pure_error`; the bias per
sequence was off by ~2 x its standard error behind that mocap, the mocap's angle error times the body rate). The
axes are pooled, then tau^2 is floored at 0 (the simulator draws one spread for the three axes).

The held-out sequences count only where every named sensor constant transferred to them (the held-out agreement's p
at least TRANSFER_P_MIN, `transfer`): refitted on a held-out sequence alone, a constant that does not hold there
trades with the bias. TUM-VI with room 3 held out (a nonlinearity, p 4.8e-7) gave a spread of 0.52 deg/s where room
3's stretches, fitted with the bias alone in the other two splits, agree with the rest (spread 0).
"""

from __future__ import annotations

import numpy as np

from gyrodenoise.discrepancy.fitted_model import Selection
from gyrodenoise.discrepancy.replicates import block, replicates_of
from gyrodenoise.sim.context import FitContext

TRANSFER_P_MIN = 0.01  # a named constant's held-out agreement below this: it did not transfer


def bias_spread(sel: Selection, holdout: list[FitContext]) -> dict:
    """{'between_sequence_rad_s': the turn-on bias's spread (tau, the axes pooled), 'per_axis_rad_s' (each axis on its
    own, for the record), 'observed_std_rad_s' (the fit sequences' estimates' plain standard deviation, mean over
    axes, as written before), 'estimation_std_rad_s' (what the estimates' own errors account for, per axis),
    'se_inflation' (sqrt of the halves' chi2 / dof, at least 1), 'halves' (that chi-square; None where no sequence
    separates the bias in both halves, e.g. beside a named random walk, whose knots take a half's bias: the
    regression's covariance is then taken as it is), 'sequences'}. The held-out sequences count too, each bias
    refitted there alone (`replicates.Replicates`): the same sensor's turn-on, and two more degrees of freedom per
    axis than the fit sequences' alone; not where a named constant did not transfer ('held_out_left_out_for').
    No spread (fewer than two sequences count, or no per-sequence bias): {'between_sequence_rad_s': None, 'reason':
    one sentence saying why, 'sequences', 'fit_sequences', 'held_out_left_out' (names), 'held_out_left_out_for'}."""
    b = sel.params.get("bias", {}).get("bias_per_sequence")
    if b is None or sel.design is None:
        return {
            "between_sequence_rad_s": None,
            "reason": "the fit has no per-sequence turn-on bias (no bias in the base model)",
            "sequences": 0,
            "fit_sequences": 0,
            "held_out_left_out": [],
            "held_out_left_out_for": [],
        }
    b = np.atleast_2d(np.asarray(b, dtype=float))
    n_fit = len(b)
    reps = replicates_of(sel, holdout)
    failed = sorted(n for n, t in (sel.transfer or {}).items() if t.get("p_value", 1.0) < TRANSFER_P_MIN)
    held, skipped = [], []  # a held-out sequence that does not separate the bias on its own does not count either
    for i, fc in enumerate(holdout, start=n_fit):
        found = [] if failed else reps.estimates("bias", [i])
        held += found
        skipped += [] if found else [fc.name]
    s = n_fit + len(held)
    if s < 2:
        return {
            "between_sequence_rad_s": None,
            "reason": _no_spread_reason(n_fit, skipped, failed),
            "sequences": s,
            "fit_sequences": n_fit,
            "held_out_left_out": skipped,
            "held_out_left_out_for": failed,
        }
    cov = np.zeros((s, 3, s, 3))
    cov[:n_fit, :, :n_fit, :] = block(sel.result, sel.design.cols["bias"])[1].reshape(n_fit, 3, n_fit, 3)
    for i, (_, v) in enumerate(held, start=n_fit):  # refitted on their own data: independent of the rest
        cov[i, :, i, :] = v
    b_all = np.concatenate([b, *(c[None] for c, _ in held)])
    halves = reps.pure_error("bias")
    k2 = max(1.0, halves["chi2"] / halves["dof"]) if halves is not None else 1.0
    centre = np.eye(s) - 1.0 / s
    q = np.sum((b_all - b_all.mean(0)) ** 2, axis=0)
    err = np.array([k2 * float(np.trace(centre @ cov[:, a, :, a])) for a in range(3)])
    # pooled before the floor: a floor per axis (2 degrees of freedom each with three sequences) lifts a zero spread
    tau2 = max(0.0, float(q.sum() - err.sum()) / (3 * (s - 1)))
    return {
        "between_sequence_rad_s": float(np.sqrt(tau2)),
        "per_axis_rad_s": np.sqrt(np.maximum(0.0, (q - err) / (s - 1))).tolist(),
        "observed_std_rad_s": float(b.std(0, ddof=1).mean()) if n_fit > 1 else None,
        "estimation_std_rad_s": np.sqrt(err / (s - 1)).tolist(),
        "se_inflation": float(np.sqrt(k2)),
        "halves": halves,
        "sequences": s,
        "held_out_left_out_for": failed,  # the named constants that did not transfer (then the fit sequences alone)
    }


def _no_spread_reason(n_fit: int, skipped: list[str], failed: list[str]) -> str:
    """Why fewer than two sequences counted, in one sentence (the report's text and the JSON's 'reason')."""
    counted = f"only {n_fit} fit sequence{'s' if n_fit != 1 else ''} counted"
    if not skipped:
        left = "and no held-out sequence was given"
    elif failed:
        left = (
            f"the held-out {', '.join(skipped)} left out because {', '.join(failed)} did not transfer to them "
            f"(held-out agreement p < {TRANSFER_P_MIN:g}; refitted there it trades with their bias)"
        )
    else:
        left = f"the held-out {', '.join(skipped)} left out because none separates the bias on its own"
    return f"{counted}, {left}: a spread between sequences needs at least two"
