"""Does the model's low-pass fit the blind generator's without bias? (a check of the corner's low lean)

    python benchmarks/blind_discrepancy/corner_check.py [--draws 200] [--seeds 1 101 201 301]

For the trials sensor_lowpass_40hz and sensor_lowpass_25hz, on the fitted sequences the blind runner draws for each
runner seed (`run.py --seed`, default 1; trial seed = runner seed + the trial's index, sequences seed * 1000 + i,
3 x 60 s), the corner is fitted by least squares
(each sequence's mean removed) of the gyro against the model's low-pass (`sim.effects.SensorBandwidth.filter_rate`)
applied to the true rate at the stamps, three ways:

- noise-free: the generator's low-passed rate without noise (its analog filter on a fine grid, the sample mean);
- realised: the gyro the runner's sequences hold (their white noise and bias walk);
- fresh draws: the noise-free rate plus DRAWS new draws of the generator's low-passed white noise.

A corner off in the noise-free fit would be a model-generator mismatch; a realised corner off while the fresh draws'
mean is not would be one unlucky draw. The workflow's own fit also has the mocap's error and the nuisances; this
check isolates the gyro side. Writes benchmarks/results/blind_corner_check.{md,json}.
"""

from __future__ import annotations

import argparse
import platform
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy import optimize

sys.path.insert(0, str(Path(__file__).parent))
import generate  # noqa: E402  (beside this script)

from gyrodenoise.atomic import write_json, write_text  # noqa: E402
from gyrodenoise.sim.effects import SensorBandwidth  # noqa: E402

RESULTS = Path("benchmarks/results")
TRIALS = ("sensor_lowpass_40hz", "sensor_lowpass_25hz")
N_FIT, DURATION_S = 3, 60.0
EDGE = 100  # samples left out at each end (the filters' start)


def fit_corner(pairs: list[tuple[np.ndarray, np.ndarray]], truth_hz: float) -> float:
    """Least-squares corner of gyro ~ low-pass(rate) + a constant per sequence, within 3 % of the truth."""

    def rss(log_corner: float) -> float:
        total = 0.0
        for gyro, rate in pairs:
            r = (gyro - SensorBandwidth.filter_rate(rate, float(np.exp(log_corner)), generate.IMU_HZ))[EDGE:-EDGE]
            total += float(np.sum((r - r.mean(axis=0)) ** 2))
        return total

    bounds = (np.log(truth_hz * 0.97), np.log(truth_hz * 1.03))
    res = optimize.minimize_scalar(rss, bounds=bounds, method="bounded", options={"xatol": 1e-7})
    return float(np.exp(res.x))


def check(trial: str, draws: int, work: Path, runner_seed: int = 1) -> dict:
    hidden = generate.TRIALS[trial]
    corner = float(hidden.params["corner_hz"])
    seed = runner_seed + list(generate.TRIALS).index(trial)
    dt = 1.0 / generate.IMU_HZ
    t = np.arange(int(round(DURATION_S * generate.IMU_HZ))) * dt
    noise = generate.BASELINE["gyro_noise_density_rad_s_sqrtHz"]
    clean, realised = [], []
    for i in range(N_FIT):
        s = seed * 1000 + i
        generate.make_sequence(work / f"{trial}_{seed}" / f"seq{i:02d}", s, DURATION_S, hidden)
        motion = generate.make_motion(np.random.default_rng(s), DURATION_S)  # make_sequence's first draws
        rate = motion.body_rate(t)
        csv = work / f"{trial}_{seed}" / f"seq{i:02d}" / "mav0" / "imu0" / "data.csv"
        gyro = np.loadtxt(csv, delimiter=",", skiprows=1)[:, 1:4]
        quiet = generate.lowpassed_gyro(motion.body_rate, np.random.default_rng(0), t, dt, corner, 0.0)
        clean.append((quiet, rate))
        realised.append((gyro, rate))
    rng = np.random.default_rng(12345)
    zero = lambda tt: np.zeros((len(tt), 3))  # noqa: E731
    fresh = [
        fit_corner(
            [(q + generate.lowpassed_gyro(zero, rng, t, dt, corner, noise), r) for q, r in clean],
            corner,
        )
        for _ in range(draws)
    ]
    f = np.asarray(fresh)
    return {
        "trial": trial,
        "truth_hz": corner,
        "runner_seed": runner_seed,
        "seed": seed,
        "noise_free_hz": fit_corner(clean, corner),
        "realised_hz": fit_corner(realised, corner),
        "fresh_draws": draws,
        "fresh_mean_hz": float(f.mean()),
        "fresh_se_hz": float(f.std(ddof=1) / np.sqrt(draws)),
        "fresh_sd_hz": float(f.std(ddof=1)),
        "fresh_share_below": float(np.mean(f < corner)),
        "fresh_hz": fresh,
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--draws", type=int, default=200, help="fresh white-noise draws per trial")
    ap.add_argument("--seeds", type=int, nargs="+", default=[1], help="runner seeds (`run.py --seed`)")
    ap.add_argument("--results", type=Path, default=RESULTS)
    a = ap.parse_args(argv)
    start = time.time()
    with tempfile.TemporaryDirectory() as tmp:
        rows = [check(trial, a.draws, Path(tmp), s) for s in a.seeds for trial in TRIALS]
    machine = f"{platform.node()} ({platform.machine()}, {platform.python_version()})"
    out = {"rows": rows, "wall_s": time.time() - start, "machine": machine}
    write_json(a.results / "blind_corner_check.json", out)
    seeds = " ".join(map(str, a.seeds))
    lines = [
        "# The low-pass corner: model against the blind generator, gyro side only",
        "",
        f"`python benchmarks/blind_discrepancy/corner_check.py --draws {a.draws} --seeds {seeds}` "
        f"({out['wall_s']:.0f} s, {machine}). "
        "Least-squares corner of each trial's 3 fitted sequences (runner seed as listed) against the model's low-pass "
        "of the true rate; the fresh draws keep the motion and draw the white noise anew.",
        "",
        "| trial | runner seed | truth (Hz) | noise-free | realised (runner's gyro) | fresh draws: mean ± se (sd) "
        "| below truth |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['trial']} | {r['runner_seed']} | {r['truth_hz']:g} | {r['noise_free_hz']:.4f} | "
            f"{r['realised_hz']:.4f} | "
            f"{r['fresh_mean_hz']:.4f} ± {r['fresh_se_hz']:.4f} ({r['fresh_sd_hz']:.4f}) | "
            f"{r['fresh_share_below']:.0%} of {r['fresh_draws']} |"
        )
    write_text(a.results / "blind_corner_check.md", "\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
