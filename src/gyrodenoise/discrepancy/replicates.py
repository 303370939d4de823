"""Refits of the selected model on parts of the data: each sequence alone, and each half of a sequence.

Why: the regression's standard errors take the residual to be what the noise model says. Behind a Vicon-like mocap
(0.2 deg) they were about 1.3-2 times too small on the test world's procedural flights, for sensor constants and the
per-sequence bias alike (the mocap's angle error times the body rate is an error of the reconstructed rate that is
flat at low frequencies, where the reconstruction error's model has almost none). How far off they are can be read
from the data. The two halves of one sequence share every sensor constant and the turn-on bias, so their estimates
differ by estimation error alone (`pure_error`); sequences of one sensor differ by that and by how an estimate moves
with the motion (`among`). Both are chi-squares against the regression's covariances: divided by their degrees of
freedom, the factor by which those variances fall short.
"""

from __future__ import annotations

from dataclasses import replace
from functools import cached_property

import numpy as np

from gyrodenoise.discrepancy.design import Design, FitResult, row_mask, sensor_view
from gyrodenoise.discrepancy.fitted_model import Selection
from gyrodenoise.sim.context import FitContext

Estimate = tuple[np.ndarray, np.ndarray]  # coefficients and their covariance


def block(res: FitResult, cols: np.ndarray) -> Estimate:
    """Coefficients and covariance of global columns `cols` in fit `res`."""
    pos = {int(g): i for i, g in enumerate(res.idx)}
    p = np.array([pos[int(c)] for c in np.ravel(cols)])
    return res.coef[np.ravel(cols)], res.cov[np.ix_(p, p)]


def chi2_of(a: Estimate, b: Estimate) -> float:
    """Chi-square of the difference of two independent estimates against their summed covariance."""
    d = a[0] - b[0]
    return float(d @ np.linalg.pinv(a[1] + b[1], hermitian=True) @ d)


class Replicates:
    """The selection's regression model refitted on each of `views` alone (contexts as the model sees them: through
    a named sensor low-pass already) and on each half of each; computed when first asked, read per effect. `key`: the
    held-out sequences' names it was made for (`replicates_of`)."""

    def __init__(self, sel: Selection, views: list[FitContext], key: tuple[str, ...] = ()) -> None:
        self.sel, self.views, self.key = sel, views, key
        self.regress = [n for n in sel.selected if not sel.effects[n].stochastic]

    def _fit(self, fc: FitContext) -> tuple[Design, FitResult]:
        d = Design([fc], {n: self.sel.effects[n] for n in self.regress}, self.sel.sigma)
        return d, d.fit(self.regress)

    @cached_property
    def whole(self) -> list[tuple[Design, FitResult]]:
        return [self._fit(fc) for fc in self.views]

    @cached_property
    def halves(self) -> list[list[tuple[Design, FitResult]]]:
        out = []
        for fc in self.views:
            n = len(fc.t)
            parts = []
            for part in (slice(0, n // 2), slice(n // 2, n)):
                keep = np.zeros((n, 3), dtype=bool)
                keep[part] = True
                parts.append(self._fit(replace(fc, extra=fc.extra | {"row_mask": row_mask(fc) & keep})))
            out.append(parts)
        return out

    def _estimate(self, fitted: tuple[Design, FitResult], name: str) -> Estimate | None:
        d, r = fitted
        others = [n for n in self.regress if n != name]
        if not np.all(np.isfinite(d.conditional_se(others, name, 1.0))):
            return None  # this part alone cannot separate it from the others
        return block(r, d.cols[name])

    def estimates(self, name: str, which: list[int] | None = None) -> list[Estimate]:
        """`name`'s estimate from each sequence `which` (default all) alone, where that sequence separates it."""
        idx = range(len(self.views)) if which is None else which
        found = [self._estimate(self.whole[i], name) for i in idx]
        return [e for e in found if e is not None]

    def half_pairs(self, name: str) -> list[tuple[Estimate, Estimate]]:
        """`name`'s estimates from the two halves of each sequence where both separate it. A half's fit counts the
        other half's zeroed rows in its residual variance, which halves it: its covariance is taken at the whole
        sequence's residual variance instead (the noise per row is the sensor's, whatever is left out)."""
        out = []
        for whole, halves in zip(self.whole, self.halves, strict=True):
            s2 = whole[1].rss / max(whole[1].n - whole[1].k, 1)
            pair = []
            for fitted in halves:
                e = self._estimate(fitted, name)
                if e is None:
                    break
                s2_half = fitted[1].rss / max(fitted[1].n - fitted[1].k, 1)
                pair.append((e[0], e[1] * s2 / s2_half))
            if len(pair) == 2:
                out.append((pair[0], pair[1]))
        return out

    def pure_error(self, name: str) -> dict | None:
        """Chi-square of the halves' disagreement, summed over the sequences (None: no sequence separates `name` in
        both halves). chi2 / dof is the factor by which the regression's variances fall short, from estimation error
        alone."""
        pairs = self.half_pairs(name)
        if not pairs:
            return None
        chi2 = sum(chi2_of(a, b) for a, b in pairs)
        dof = sum(len(a[0]) for a, _ in pairs)
        return {"chi2": chi2, "dof": dof, "birge_ratio": float(np.sqrt(chi2 / dof)), "sequences": len(pairs)}


def among(estimates: list[Estimate]) -> dict | None:
    """Chi-square of the sequences' estimates about their precision-weighted mean, (len - 1) x k degrees of freedom
    (None: fewer than two)."""
    if len(estimates) < 2:
        return None
    w = [np.linalg.pinv(v, hermitian=True) for _, v in estimates]
    mean = np.linalg.pinv(sum(w), hermitian=True) @ sum(wi @ c for wi, (c, _) in zip(w, estimates, strict=True))
    chi2 = float(sum((c - mean) @ wi @ (c - mean) for wi, (c, _) in zip(w, estimates, strict=True)))
    dof = (len(estimates) - 1) * len(mean)
    return {"chi2": chi2, "dof": dof, "birge_ratio": float(np.sqrt(chi2 / dof)), "sequences": len(estimates)}


def views_of(sel: Selection, holdout: list[FitContext]) -> list[FitContext]:
    """The fit sequences as the final design sees them, then the held-out ones through the same sensor low-pass."""
    return [*sel.design.fcs, *(sensor_view(fc, sel.corner_hz) for fc in holdout)]


def replicates_of(sel: Selection, holdout: list[FitContext]) -> Replicates:
    """The selection's `Replicates` over its fit sequences and `holdout`, made once and kept on it (`sel.replicates`):
    the held-out check and the bias spread each refitted every sequence and half before, 1-3 s each."""
    key = tuple(fc.name for fc in holdout)
    found = sel.replicates
    if not isinstance(found, Replicates) or found.sel is not sel or found.key != key:
        found = sel.replicates = Replicates(sel, views_of(sel, holdout), key)
    return found
