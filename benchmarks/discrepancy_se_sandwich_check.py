"""Would the corner's colour correction also calibrate the regression SEs? (a check; nothing in the package uses it)

    python benchmarks/discrepancy_se_sandwich_check.py > benchmarks/results/discrepancy_se_sandwich_check.txt

The EuRoC-replay cases of benchmarks/discrepancy_se_calibration.py (`--first-seed 10`: seeds 2010-2012, 10 null
draws, one candidate each). For each named effect's coefficients, z with the regression's SE (s2 G^-1, the rows
taken as white: `z_raw` there) against z with a sandwich covariance G^-1 B G^-1 over the fit's Fourier rows,
B = sum V x x' with V the residual's local mean square within +- 0.5 Hz (the estimate `spectral.colour_factor`
uses for the corner). Printed: per fit the RMS z both ways and the ratio sandwich / regression SE per coefficient,
then per effect pooled.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
import discrepancy_se_calibration as se_cal  # noqa: E402  (beside this script)

from gyrodenoise.discrepancy.compare import load_fit_context  # noqa: E402
from gyrodenoise.discrepancy.design import residuals_after, spectral_rows  # noqa: E402
from gyrodenoise.discrepancy.spectral import local_mean_square  # noqa: E402
from gyrodenoise.discrepancy.workflow import decide  # noqa: E402
from gyrodenoise.discrepancy.worldcases import (  # noqa: E402
    FIT_FLIGHT,
    HOLDOUT_FLIGHT,
    WORLD_CASES,
    _truth_value,
    make_world,
)

SMOOTH_HZ = 0.5
SEEDS = (2010, 2011, 2012)  # the replay seeds of `discrepancy_se_calibration.py --first-seed 10`


def fourier_rows(fc, X: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Weighted columns X (3N, k) and residual r (3N,) as the fit's Fourier rows (M, 3, k), (M, 3) and frequencies
    (M,): `design.spectral_rows`, a linear map, applied to the residual and to each column."""
    n = len(fc.t)
    rf, f = spectral_rows(fc, r.reshape(n, 3))
    Xf = np.stack([spectral_rows(fc, X[:, j].reshape(n, 3))[0] for j in range(X.shape[1])], axis=-1)
    return Xf, rf, f


def se_ratio(sel) -> dict[int, float]:
    """Sandwich / regression SE of every coefficient of the selected effects (global column -> ratio)."""
    design, res = sel.design, sel.result
    cols = design.indices(sel.selected)
    pos = {int(g): i for i, g in enumerate(cols)}
    G, B = np.zeros((len(cols), len(cols))), np.zeros((len(cols), len(cols)))
    ee, m = 0.0, 0
    resid = residuals_after(design, res, sel.selected)
    for s, fc in enumerate(design.fcs):
        X, idx = design.local_columns(s, sel.selected)
        loc = [pos[int(g)] for g in idx]
        Xf, ef, f = fourier_rows(fc, X, (resid[s] / design.sigma).reshape(-1))
        v = local_mean_square(ef, f, SMOOTH_HZ)
        for a in range(3):
            x = Xf[:, a, :]
            G[np.ix_(loc, loc)] += x.T @ x
            B[np.ix_(loc, loc)] += (x * v[:, a, None]).T @ x
        ee += float(np.sum(ef**2))
        m += ef.size
    w, V = np.linalg.eigh(G)
    keep = w > 1e-10 * w.max()
    Gi = (V[:, keep] / w[keep]) @ V[:, keep].T
    white, sandwich = np.diag(Gi) * ee / m, np.diag(Gi @ B @ Gi)
    return {g: float(np.sqrt(sandwich[i] / white[i])) for g, i in pos.items()}


def rms(z: np.ndarray) -> float:
    return float(np.sqrt(np.mean(z**2)))


def main() -> int:
    # no options; --help shows what it does instead of running it (it writes committed files)
    argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter).parse_args()
    t0 = time.time()
    pooled: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {}
    for effect in se_cal.CASES:
        case = WORLD_CASES[effect]
        for seed in SEEDS:
            with tempfile.TemporaryDirectory() as root:
                truth = make_world(root, case.specs[0], seed)
                fit, hold = [load_fit_context(root, FIT_FLIGHT)], [load_fit_context(root, HOLDOUT_FLIGHT)]
                _, sel, _ = decide(fit, hold, candidates=[effect], null_draws=10, seed=seed)
                if effect not in sel.named:
                    print(f"{effect} seed {seed}: not named")
                    continue
                true = np.ravel(_truth_value(truth, effect, case.param))
                z = np.array(se_cal._z(sel, effect, case.param, true)["z_raw"])
                ratio = se_ratio(sel)
                r = np.array([ratio[int(g)] for g in np.ravel(sel.design.cols[effect])])
                if len(r) != len(z):  # a parameter that is not one coefficient each: not comparable here
                    print(f"{effect} seed {seed}: {len(r)} coefficients, {len(z)} parameters; skipped")
                    continue
                pooled.setdefault(effect, []).append((z, z / r))
                print(
                    f"{effect} seed {seed}: RMS z regression SE {rms(z):.2f}, sandwich {rms(z / r):.2f}; "
                    f"sandwich / regression SE {np.array2string(r, precision=2)}",
                    flush=True,
                )
    print("pooled over seeds:")
    for effect, runs in pooled.items():
        z, zs = np.concatenate([a for a, _ in runs]), np.concatenate([b for _, b in runs])
        print(f"  {effect}: RMS z regression SE {rms(z):.2f} -> sandwich {rms(zs):.2f} ({len(z)} coefficients)")
    print(f"wall {time.time() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
