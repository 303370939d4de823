"""A named time offset or a sensor low-pass: which one the motion says, and the charge the low-pass pays.

Both delay the motion alike at low frequencies; only the low-pass's magnitude droop, (f / corner)^2 / 2, tells them
apart. Once the greedy selection (`rank.select_effects`) has named a time offset, `choose` fits the low-pass alone
and the low-pass beside an offset, each corner searched on its profile (`LowpassProfile`), and keeps the explanation
the data prefer. A low-pass applied to the reconstructed true rate also smooths the ground truth's own noise, which
the sensor never saw: `truth_error_smoothing` is that gain, charged to every low-pass fit (here and in
`rank.score_step`).
The final backward check of the selection (`rank._recheck_named`) may still remove a time offset the choice kept;
`after_backward_check` then marks the choice's record, so that the report's notes speak only of what is named.
"""

from __future__ import annotations

import copy
from collections.abc import Callable, Mapping

import numpy as np

from gyrodenoise.discrepancy.design import Design, FitResult, residuals_after, sensor_view, spectral_rows
from gyrodenoise.discrepancy.identifiability import delay_or_lowpass
from gyrodenoise.discrepancy.reconstruction import row_frequencies
from gyrodenoise.discrepancy.spectral import CORNER_STEP, colour_factor, corner_se, search_log_corner
from gyrodenoise.sim.context import FitContext
from gyrodenoise.sim.effects import Effect, SensorBandwidth

# The low-pass replaces a named time offset when its delta BIC against it is at least this. Both explanations have one
# parameter, so BIC's penalty cancels and the better fit is kept; the threshold that guards a detection was cleared
# when the delay was named. (It was the detection threshold, 10, until session 54: with the offset's first-estimate
# secant, which handed the low-pass 2-11, the two nearly cancelled; without it, 10 kept the offset for a 40 Hz low-pass
# on 17 of 40 close calls of 2 x 40 s, `benchmarks/results/blind_close_calls{,_seed320}_session54.md`.)
SWITCH_THRESHOLD = 0.0


def choose(
    design: Design,
    final: FitResult,
    effects: dict[str, Effect],
    selected: list[str],
    sigma: np.ndarray,
    fcs: list[FitContext],
    threshold: float,
) -> tuple[Design, FitResult, list[FitContext], dict | None]:
    """A named time offset that delays (IMU stamps late) is also what a sensor low-pass does at low
    frequencies. The expected delta BIC between the two on this motion (`delay_or_lowpass`) says
    whether the data can tell them apart; if not, the selection keeps the time offset and reports
    the equivalence (delay and equivalent corner). If so, three explanations are fitted, each corner
    searched: the low-pass alone (no time offset), and the low-pass with a time offset beside it
    (a sensor's filter and late stamps at once: the droop reads the corner, the offset takes the rest
    of the delay). The pair is kept if it beats the better single explanation by `threshold` in BIC
    (one parameter more); else the low-pass replaces the offset if it fits better (`SWITCH_THRESHOLD`).

    A low-pass applied to a reconstructed true rate also smooths that rate's own error (ground-truth
    noise, `reconstruction`), which the sensor never saw: under either explanation that lowers the
    low-pass's residual by about the error power it removes (`truth_error_smoothing`), so that
    amount is added back to the low-pass's residual before the explanations are compared.
    Returns the (possibly new) design, fit, sensor view of `fcs` and the numbers."""
    delta = float(final.coef[design.cols["time_offset"]][0])
    view = design.fcs
    if delta <= 0:
        return design, final, view, None
    s2 = final.rss / max(final.n - final.k, 1)
    dol = delay_or_lowpass(design, selected, s2, delta, threshold)
    out = dol.as_dict() | {"sentence": dol.sentence(), "kept": "time_offset"}
    if not dol.separable:
        return design, final, view, out
    others = [n for n in selected if n != "time_offset"]
    alone = LowpassProfile(fcs, effects, others, sigma)
    # a coarse grid around the delay's equivalent corner (the low-pass alone); with an offset beside it the
    # corner is above that (the offset takes the rest of the delay) or a little below it (stamps early)
    u, se_white, colour = alone.search(np.log(dol.corner_hz * np.geomspace(0.25, 4.0, 17)), final.n)
    best = alone.fits[u]
    secant_at = effects["time_offset"].delta_ref
    # the offset alone again, its secant at its fitted delay (as the pair's is): what the low-pass and the pair must
    # beat is the offset, not the first estimate's secant. That estimate regresses on the truth's noisy angular
    # acceleration and falls short (3.8 ms for 4 ms behind a 0.05 deg mocap), and the secant's misfit then handed the
    # low-pass 2-5 in delta BIC on 2 x 40 s, 4-11 on 3 x 60 s (an 8 ms offset alone gave the pair 19, a 318 Hz corner)
    effects["time_offset"].delta_ref = delta
    rss_offset = min(final.rss, Design(view, {n: effects[n] for n in selected}, sigma).fit(selected).rss)
    dbic = final.n * np.log(rss_offset / best[0])
    out |= {
        "delta_bic_lowpass_vs_offset": float(dbic),
        "switch_threshold": SWITCH_THRESHOLD,
        "offset_secant_refit_bic": float(final.n * np.log(final.rss / rss_offset)),
        "lowpass_corner_hz": best[1],
        "lowpass_corner_se_hz": se_white * colour,
        "lowpass_corner_se_white_hz": se_white,
        "lowpass_corner_se_colour_factor": colour,
        # what the low-pass's smoothing of the truth's error alone would have been worth (0: exact truth)
        "truth_error_smoothing_bic": float(final.n * np.log(best[0] / (best[0] - best[3]))),
    }
    pair = LowpassProfile(fcs, effects, selected, sigma, total_delay_s=delta)
    uj, se_white_j, colour_j = pair.search(np.log(dol.corner_hz * np.geomspace(0.5, 16.0, 21)), final.n)
    joint = pair.fits[uj]
    dbic_pair = final.n * np.log(min(rss_offset, best[0]) / joint[0]) - np.log(final.n)
    # the droop's information at the pair's corner, at the pair's residual variance: a corner the motion cannot
    # read is not named, whatever the statistic says (and it is the spread of that statistic: `cautions`)
    s2_pair = joint[2][1].rss / max(joint[2][1].n - joint[2][1].k, 1)
    effects["time_offset"].delta_ref = pair.secant_delay(joint[1])  # the offset's regressor of the pair's fit
    droop = delay_or_lowpass(design, selected, s2_pair, 1 / (2 * np.pi * joint[1]), threshold).expected_delta_bic
    out |= {"delta_bic_both_vs_one": float(dbic_pair), "both_expected_delta_bic": float(droop)}
    if dbic_pair >= threshold and droop >= threshold:
        d, r, v = joint[2]
        # the offset moves with the corner (the two share the delay): its SE takes the corner's part,
        # var = var(offset | corner) + (d offset / d log corner)^2 var(log corner)
        slope = (pair.coef("time_offset", uj + CORNER_STEP) - pair.coef("time_offset", uj - CORNER_STEP)) / (
            2 * CORNER_STEP
        )
        se_u = se_white_j * colour_j / joint[1]
        out |= {
            "kept": "both",
            "both_corner_hz": joint[1],
            "both_corner_se_hz": se_white_j * colour_j,
            "both_corner_se_white_hz": se_white_j,
            "both_corner_se_colour_factor": colour_j,
            "both_delay_s": pair.coef("time_offset", uj),
            "both_delay_se_from_corner_s": float(abs(slope) * se_u),
        }
        selected.append("sensor_bandwidth")
        effects["sensor_bandwidth"].params["corner_hz"] = np.asarray(joint[1])
        # later designs built from `effects` take the kept pair's regressor (set above, for the droop)
        return d, r, v, out
    effects["time_offset"].delta_ref = secant_at  # the offset alone's regressor again (the pair's was per corner)
    if dbic < SWITCH_THRESHOLD:
        return design, final, view, out
    selected.remove("time_offset")
    selected.append("sensor_bandwidth")
    effects["sensor_bandwidth"].params["corner_hz"] = np.asarray(best[1])
    d, r, v = best[2]
    return d, r, v, out | {"kept": "sensor_bandwidth"}


def after_backward_check(out: dict | None, selected: list[str]) -> dict | None:
    """The choice's record (`choose`) once the selection's final backward check has run. Where that check removed a
    time offset the choice kept (alone, or beside the low-pass), the record says so (`removed_by_backward_check`) and
    `kept` stays what the choice decided: the equivalence sentence, the margin caution and the corner's words read
    the flag (an offset no longer named is neither equivalent to a low-pass nor part of a pair). Else `out` as it
    is."""
    if out is None or out["kept"] not in ("time_offset", "both") or "time_offset" in selected:
        return out
    return out | {"removed_by_backward_check": "time_offset"}


class LowpassProfile:
    """The fit of the regression effects `fitted` seen through a sensor low-pass of corner exp(u), as a function of
    u: rss plus the truth-error smoothing charge (`truth_error_smoothing`), cached per u as (rss + charge, corner,
    (design, fit, view), charge). The design holds the low-pass too (stochastic: no columns), as every selected
    effect's design does: `fill_params` asks it for the columns of all of them.

    `total_delay_s`: a time offset is fitted beside the low-pass, and its regressor (`TimeOffset`, a secant through
    w(t - delta_ref)) is taken at the delay the low-pass leaves to it, total_delay_s - 1 / (2 pi corner). A secant
    taken at the whole delay would droop by itself where the fitted offset is shorter (the mean of w(t) and
    w(t - 2 delta) is a low-pass), and the corner would take what is left of the droop."""

    def __init__(
        self,
        fcs: list[FitContext],
        effects: dict[str, Effect],
        fitted: list[str],
        sigma: np.ndarray,
        total_delay_s: float | None = None,
    ):
        self.fcs, self.effects, self.fitted, self.sigma = fcs, effects, list(fitted), sigma
        self.total_delay_s = total_delay_s
        self.fits: dict[float, tuple] = {}

    def secant_delay(self, corner_hz: float) -> float:
        """The delay a low-pass of this corner leaves to the offset beside it: where the offset's secant is taken."""
        limit = self.effects["time_offset"].PRIOR[1]
        return float(np.clip(self.total_delay_s - 1 / (2 * np.pi * corner_hz), -limit, limit))

    def __call__(self, u: float) -> float:
        c = float(np.exp(u))
        if u not in self.fits:
            v = [sensor_view(fc, c) for fc in self.fcs]
            chosen = {n: self.effects[n] for n in [*self.fitted, "sensor_bandwidth"]}
            if self.total_delay_s is not None:  # each corner's design keeps its own secant (columns are built lazily)
                chosen["time_offset"] = copy.copy(chosen["time_offset"])
                chosen["time_offset"].delta_ref = self.secant_delay(c)
            d = Design(v, chosen, self.sigma)
            r = d.fit(self.fitted)
            g = float(truth_error_smoothing(self.fcs, self.sigma, np.array([c]))[0])
            self.fits[u] = (r.rss + g, c, (d, r, v), g)
        return self.fits[u][0]

    def search(self, grid: np.ndarray, n: int) -> tuple[float, float, float]:
        """The best log corner on `grid` (`spectral.search_log_corner`), with its profile standard error (rows taken
        as white) and the colour factor of its residual (`corner_colour_factor`)."""
        u = search_log_corner(self, grid)
        se_white = profile_corner_se(self, u, n)
        return u, se_white, corner_colour_factor(self.fits, u, self.fitted, self.sigma)

    def coef(self, name: str, u: float) -> float:
        """The first coefficient of effect `name` in the fit at log corner u."""
        self(u)
        d, r, _ = self.fits[u][2]
        return float(r.coef[d.cols[name]][0])


def corner_colour_factor(fits: Mapping[float, tuple], u: float, others: list[str], sigma: np.ndarray) -> float:
    """`spectral.colour_factor` of the low-pass fit at corner exp(u): its residual's Fourier rows and their
    derivative in log corner, by central differences of the refits `profile_corner_se` made (the other effects refitted
    at each corner, so the derivative is the profile's)."""
    rows = {}
    for d in (-CORNER_STEP, 0.0, CORNER_STEP):
        design, res, views = fits[u + d][2]
        resid = residuals_after(design, res, others, views)
        rows[d] = [spectral_rows(fc, e / sigma) for fc, e in zip(views, resid, strict=True)]
    slopes = [
        -(up[0] - down[0]) / (2 * CORNER_STEP) for up, down in zip(rows[CORNER_STEP], rows[-CORNER_STEP], strict=True)
    ]
    return colour_factor([e for e, _ in rows[0.0]], slopes, [f for _, f in rows[0.0]])


def profile_corner_se(rss_at: Callable[[float], float], u: float, n: int) -> float:
    """Standard error (Hz) of a corner exp(u) fitted by least squares on n rows (`spectral.corner_se`) from the
    profile log-likelihood -(n/2) log rss, the scale of the selection's BIC."""
    ll = [-0.5 * n * np.log(rss_at(u + d)) for d in (-CORNER_STEP, 0.0, CORNER_STEP)]
    return corner_se(*ll, u)


def truth_error_smoothing(fcs: list[FitContext], sigma: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """(len(corners),) expected drop of a fit's weighted residual sum of squares when the reconstructed true rate is
    seen through a first-order low-pass of each corner (`SensorBandwidth`), from the ground truth's own noise alone:
    E ||rows(e)||^2 - ||rows(H e)||^2 = sum over the fit's rows (`fit_rows`) and axes of (1 - |H(f)|^2) times the
    row's weighted noise power kappa N(f) (rate / 2) / sigma^2 w(f)^2, N the ground-truth noise part of the
    reconstruction error (`ReconstructionBand.noise_psd`). Motion the spline smoothed away is not counted: the gyro
    has it and the truth lacks it under either explanation, so the low-pass gains nothing there. The rows' edge
    projection and masked samples are neglected (a few rows). Zeros for an exact ground truth."""
    out = np.zeros(len(corners))
    for fc in fcs:
        b, kappa, w = fc.extra.get("band"), fc.extra.get("nuisance_level"), fc.extra.get("row_weights")
        if b is None or b.exact or kappa is None or w is None:
            continue
        f = row_frequencies(len(fc.t), fc.rate_hz, fc.extra.get("band_hz"))
        power = np.sum(kappa * b.noise_psd(f) * (fc.rate_hz / 2) / sigma**2 * w**2, axis=1)
        for i, c in enumerate(corners):
            h2 = np.abs(SensorBandwidth.response(f, float(c))) ** 2
            out[i] += float(np.sum((1.0 - h2) * power))
    return out
