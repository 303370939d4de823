"""Bias instability: is the bias's slow wander a flicker floor (a flat Allan deviation) the model lacks?

The greedy selection names a wandering bias a random walk (its knots absorb any slow wander). What tells a
flicker bias (a datasheet's "bias instability", one-sided PSD h / f) from a random walk (h / f^2) is the shape
of the Allan variance of what the deterministic model leaves, the bias's wander kept:

    AVAR(tau) = N^2 / tau + F^2 + K^2 tau / 3  (+ 3 Q^2 / tau^2 behind a reconstructed truth),

white noise N, flicker floor F, rate random walk K and the truth's angle noise Q. F^2 is fitted by weighted least
squares over the cluster times the flights offer, and judged against its own distribution under the selected
model (a parametric bootstrap: `DRAWS` re-simulations of the fit sequences through `simulate_like`, the same
refit, the same fit), not against the least-squares standard errors: the cluster times' variances are correlated
and a reconstructed truth's error is not exactly 3 Q^2 / tau^2. Named when the floor lies `MIN_Z` of the null's
standard deviations above the null's mean on an axis, with a practical share (the practical minimum of the Allan
variance at the longest cluster time), and as far above on that axis on the held-out sequences against their own
re-simulations (`MIN_Z_HOLDOUT`). A random walk the selection named is then judged the same
way against re-simulations with the floor in its place: kept when its K^2 lies `MIN_Z` above theirs and is at
least `STANDIN_RATIO` times their mean, else replaced by the floor (the knots had stood in for the flicker); a
band-limited vibration likewise, by its band's power.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator

import numpy as np

from gyrodenoise.allan import allan_taus, pooled_allan, root_with_se
from gyrodenoise.discrepancy.design import band_edges, nuisance_of, row_masks
from gyrodenoise.discrepancy.rank import Selection
from gyrodenoise.discrepancy.reconstruction import band_limit
from gyrodenoise.discrepancy.resimulate import as_measured, simulate_like, without_walk_knots
from gyrodenoise.discrepancy.spectral import fit_band
from gyrodenoise.sim.context import FitContext
from gyrodenoise.sim.effects import BiasInstability

NAME = "bias_instability"
DRAWS = 40  # re-simulations per null distribution (each: every fit sequence once)
MIN_Z = 3.5  # the floor (or the walk, the band) this many null standard deviations above the null's mean
# and the floor on the same axis of the held-out sequences, against their own re-simulations. As strict as on the fit
# sequences: behind a noisy mocap the null is not calibrated (blind trials with no floor hidden gave fit z up to 4.9 on
# one axis, held-out z up to 3.4 on another), and a floor is a property of the sensor, there on every flight
MIN_Z_HOLDOUT = MIN_Z
# a walk or band the floor may have stood in for stays when it stands out (MIN_Z) and its power is at least this many
# times what re-simulations with the floor in its place make: at a high signal-to-noise ratio any small difference
# between the floor's true shape and the simulated one stands out, and a z alone would keep the stand-in
STANDIN_RATIO = 2.0
# below this, on the fit or the held-out flights, the measured floor lies far under anything the selected model's
# re-simulations make (their slow wander, e.g. the truth's reconstruction error drawn at its fitted level, is not these
# flights'): not judged, not identifiable. Test-world flights gave z >= -3.6; EuRoC's default split -19 to -50 (its
# truth follows the gyro), fitted on V1_02 alone -127 to -529 on the held-out V2_03
MISMATCH_Z = 2 * MIN_Z
MIN_TAUS = 6  # cluster times the fit of 3-4 terms needs at least
TAU_MIN_S, TAU_MAX_S = 1.0, 1000.0  # the simulated floor's band: flights of minutes cannot say where it ends


def split_candidates(candidates: list[str] | None) -> tuple[list[str] | None, bool]:
    """(the regression selection's candidates, whether the floor is judged): None (the whole vocabulary) judges it,
    a list only when it names `NAME`."""
    if candidates is None:
        return None, True
    return [c for c in candidates if c != NAME], NAME in candidates


def wander_residuals(sel: Selection, fcs: list[FitContext]) -> list[np.ndarray]:
    """What the deterministic model leaves on each sequence with the bias's wander kept: its constants and
    per-sequence nuisances refitted as on a held-out sequence, the random walk's knots left out."""
    return [fc.residual - without_walk_knots(sel, fc) for fc in fcs]


def allan_terms(residuals: list[np.ndarray], fcs: list[FitContext], angle_noise: bool) -> dict:
    """Weighted least-squares fit of N^2, F^2, K^2 (and Q^2) per axis to the pooled Allan variance of `residuals`,
    in the compared band (cluster times >= 1 / band edge). Returns {'white2', 'floor2', 'walk2'} each (3,), the
    Allan variance at the longest cluster time ('longest', 'longest_tau_s'); None with fewer than `MIN_TAUS` cluster
    times (too short, or not finite)."""
    rate = fcs[0].rate_hz
    f_max = min(fc.extra.get("band_hz") or rate / 2 for fc in fcs)
    if f_max < rate / 2:
        residuals = [band_limit(r, rate, f_max) for r in residuals]
    # cluster times up to the longest sequence's (`pooled_allan` leaves a sequence out where it is too short): one
    # short stretch would otherwise cap every sequence's at its own
    taus = allan_taus(max(len(r) for r in residuals), rate, per_octave=2)
    taus = taus[taus >= 1.0 / f_max]
    av = pooled_allan(residuals, rate, taus) ** 2
    if (np.isfinite(av).all(1) & (av > 0).all(1)).sum() < MIN_TAUS:
        return None
    span = sum(len(r) for r in residuals) / rate
    rel = np.sqrt(2 * taus / span + 2.0 / (span * rate))  # relative std of each cluster time's variance
    cols = [1 / taus, np.ones_like(taus), taus / 3] + ([3 / taus**2] if angle_noise else [])
    A = np.stack(cols, 1)
    coef = np.full((3, A.shape[1]), np.nan)
    for i in range(3):
        ok = np.isfinite(av[:, i]) & (av[:, i] > 0)
        w = 1.0 / (rel[ok] * av[ok, i])
        coef[i], *_ = np.linalg.lstsq(A[ok] * w[:, None], av[ok, i] * w, rcond=None)
    last = int(np.flatnonzero(np.isfinite(av).all(1) & (av > 0).all(1))[-1])
    return {
        "white2": coef[:, 0],
        "floor2": coef[:, 1],
        "walk2": coef[:, 2],
        "longest": av[last],  # the Allan variance at the longest cluster time: the floor's share is read there
        "longest_tau_s": float(taus[last]),
    }


def _redraws(sel: Selection, fcs: list[FitContext], seed: int, tag: int) -> Iterator[list[FitContext]]:
    """DRAWS re-simulations of sequences `fcs` under `sel` (its deterministic part refitted without the walk's knots),
    each as the list of re-simulated sequences; draw d of sequence s from the generator (seed, tag, d, s)."""
    free = [without_walk_knots(sel, fc) for fc in fcs]
    for d in range(DRAWS):  # (only the gyro is used: the prediction given is the walk-free one too)
        yield [
            as_measured(
                fc, simulate_like(sel, fc, np.random.default_rng([seed, tag, d, s]), free[s], walk_free=free[s])[0]
            )
            for s, fc in enumerate(fcs)
        ]


def _null(sel: Selection, fcs: list[FitContext], angle_noise: bool, seed: int, tag: int) -> dict:
    """The Allan terms of DRAWS re-simulations of the fit sequences under `sel` (each term (DRAWS, 3))."""
    terms: dict[str, list] = {"floor2": [], "walk2": []}
    for sims in _redraws(sel, fcs, seed, tag):
        t = allan_terms(wander_residuals(sel, sims), sims, angle_noise)  # as long as the measured: not None
        for k in terms:
            terms[k].append(t[k])
    return {k: np.asarray(v) for k, v in terms.items()}


def _z(value: np.ndarray, null: np.ndarray) -> np.ndarray:
    return (value - null.mean(0)) / np.maximum(null.std(0, ddof=1), 1e-300)


def _without(sel: Selection, *names: str) -> Selection:
    """A shallow copy of `sel` without the effects `names` (selected and parameters)."""
    out = dataclasses.replace(sel, selected=[n for n in sel.selected if n not in names])
    out.params = {k: v for k, v in sel.params.items() if k not in names}
    return out


def _drop(sel: Selection, name: str) -> None:
    sel.selected = [n for n in sel.selected if n != name]
    sel.named = [n for n in sel.named if n != name]
    for d in (sel.params, sel.se, sel.fitted):
        d.pop(name, None)


def _band_stat(sel: Selection, residuals: list[np.ndarray], fcs: list[FitContext], band: tuple[float, float]) -> float:
    """Power (summed over the axes) of a band of fixed centre and width, its level fitted over the floor."""
    fit = fit_band(
        residuals,
        fcs[0].rate_hz,
        row_masks(fcs),
        starts=[band],
        bands=band_edges(fcs),
        floor_corner_hz=sel.corner_hz,
        nuisance=nuisance_of(fcs, sel.corner_hz),
        fixed_band=True,
    )
    return 0.0 if fit is None else float(np.clip(fit.power, 0.0, None).sum())


def _vibration_holds(sel: Selection, fcs: list[FitContext], seed: int) -> dict:
    """Is a named band-limited vibration more than the flicker floor's colour? Its band's power on the fit sequences
    against re-simulations with the floor and without the band (nor a walk, judged after it)."""
    v = sel.params["vibration"]
    band = (float(v["frequency_hz"]), float(v["bandwidth_hz"]))
    measured = _band_stat(sel, wander_residuals(sel, fcs), fcs, band)
    alt = _without(sel, "vibration", "bias_random_walk")
    sims_per_draw = _redraws(alt, fcs, seed, 13)
    null = np.asarray([_band_stat(alt, wander_residuals(alt, sims), sims, band) for sims in sims_per_draw])
    z = float(_z(measured, null))
    ratio = measured / max(null.mean(), 1e-300)
    keep = z >= MIN_Z and ratio >= STANDIN_RATIO
    return {"band_hz": list(band), "power_rad2_s2": measured, "z": z, "ratio": ratio, "kept": bool(keep)}


def _mismatch(sel: Selection, out: dict) -> dict:
    """The model's re-simulations wander far more than the flights (fit or held-out): no null to judge a floor by."""
    out["null_mismatch"] = True
    sel.not_identifiable = sorted({*sel.not_identifiable, NAME})
    return out


def check(sel: Selection, fit: list[FitContext], holdout: list[FitContext], min_gain: float, seed: int = 0) -> dict:
    """Judge a flicker floor on the fit sequences and on the held-out ones (`MIN_Z`, `MIN_Z_HOLDOUT`), with a
    practical share of the Allan variance at the longest compared cluster time (at least `min_gain`). When it is
    named, put it into `sel` (params, standard errors, named) and judge again what it may have stood in for: a
    random walk and a band-limited vibration the selection named are kept only when they still stand out against
    re-simulations with the floor in their place (`MIN_Z`, `STANDIN_RATIO`). Returns the record the report keeps."""
    angle_noise = nuisance_of(fit) is not None
    measured = allan_terms(wander_residuals(sel, fit), fit, angle_noise)
    if measured is None:
        return {"named": False, "not_judged": f"fewer than {MIN_TAUS} cluster times in the compared band"}
    null = _null(sel, fit, angle_noise, seed, 11)
    z = _z(measured["floor2"], null["floor2"])
    floor2 = np.clip(measured["floor2"] - null["floor2"].mean(0), 0.0, None)  # beyond what the model already makes
    share = floor2 / measured["longest"]
    out: dict = {
        "method": f"weighted fit of the Allan variance (white, floor, walk) against {DRAWS} re-simulations each",
        "draws": DRAWS,
        "min_z": MIN_Z,
        "min_z_holdout": MIN_Z_HOLDOUT,
        "floor_z": z.tolist(),
        "floor_rad_s": np.sqrt(floor2).tolist(),
        "share_at_longest_tau": share.tolist(),
        "longest_tau_s": measured["longest_tau_s"],
        "named": False,
    }
    if (z <= -MISMATCH_Z).any():
        return _mismatch(sel, out)
    axes = (z >= MIN_Z) & (share >= min_gain)
    if not axes.any():
        return out
    if holdout:  # (computed only here: a held-out mismatch is seen only where the fit flights show a floor)
        held = allan_terms(wander_residuals(sel, holdout), holdout, angle_noise)
        if held is None:
            out["not_judged"] = f"held-out flights: fewer than {MIN_TAUS} cluster times in the compared band"
            return out
        zh = _z(held["floor2"], _null(sel, holdout, angle_noise, seed, 14)["floor2"])
        out["holdout_floor_z"] = zh.tolist()
        if (zh <= -MISMATCH_Z).any():
            return _mismatch(sel, out)
        axes &= zh >= MIN_Z_HOLDOUT  # the same axis: a sensor's floor shows on its axis in every flight
        if not axes.any():
            return out
    # a first level, beyond what the model makes without the terms the floor may have stood in for
    standins = [n for n in ("vibration", "bias_random_walk") if n in sel.named]  # a base effect stays as it is
    standins = [n for n in standins if n != "vibration" or sel.band_vibration]
    bare = _null(_without(sel, *standins), fit, angle_noise, seed, 16)["floor2"] if standins else null["floor2"]
    band = {"tau_min": np.asarray(TAU_MIN_S), "tau_max": np.asarray(TAU_MAX_S)}
    sel.params[NAME] = {"instability": np.sqrt(np.clip(measured["floor2"] - bare.mean(0), 0.0, None)), **band}
    if "vibration" in standins:
        out["vibration"] = _vibration_holds(sel, fit, seed)  # against the floor alone (no band, no walk)
        if not out["vibration"]["kept"]:
            _drop(sel, "vibration")
    if "bias_random_walk" in standins:
        # the walk beside the floor: its K^2 against re-simulations with the floor and no walk
        walk = _null(_without(sel, "bias_random_walk"), fit, angle_noise, seed, 12)["walk2"]
        zk = _z(measured["walk2"], walk)
        ratio = measured["walk2"] / np.maximum(walk.mean(0), 1e-300)
        keep = bool(((zk >= MIN_Z) & (ratio >= STANDIN_RATIO)).any())
        out["random_walk"] = {"walk_z": zk.tolist(), "ratio": ratio.tolist(), "kept": keep}
        if not out["random_walk"]["kept"]:
            _drop(sel, "bias_random_walk")
    # the floor beyond what the final model's other terms make (the first null's model when nothing was dropped), with
    # that null's spread as its standard error; on every axis (a sensor's floor is on each, if only one stood out)
    dropped = [n for n in standins if n not in sel.selected]
    rest = _null(_without(sel, NAME), fit, angle_noise, seed, 15)["floor2"] if dropped else null["floor2"]
    floor2 = np.clip(measured["floor2"] - rest.mean(0), 0.0, None)
    if dropped:  # refits of the selection's sequences (bias spread) must not hold the dropped terms
        sel.replicates = None
    if not floor2.any():  # nothing left beyond the other terms (a kept walk makes it all)
        del sel.params[NAME]
        out["floor_rad_s"] = floor2.tolist()
        return out
    out["named"] = True
    floor, floor_se = root_with_se(floor2, rest.std(0, ddof=1))
    sel.params[NAME]["instability"] = floor
    sel.se[NAME] = {"instability": floor_se}
    out["floor_rad_s"] = floor.tolist()
    sel.named.append(NAME)
    sel.fitted[NAME] = BiasInstability(**sel.params[NAME])
    return out
