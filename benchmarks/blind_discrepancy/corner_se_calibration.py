"""Is the low-pass corner's standard error calibrated? Many fresh draws of the blind generator's low-pass trials.

    python benchmarks/blind_discrepancy/corner_se_calibration.py [--draws 40] [--mocap-noise-scale 0] \
        [--first-seed 5000] [--out benchmarks/results/NAME]

For each trial (sensor_lowpass_40hz, sensor_lowpass_25hz) and each of DRAWS generator seeds (fresh motion and
noise, 3 sequences x 60 s as the blind runner fits), the workflow's selection runs in-process (base
bias,white_noise,bias_random_walk; candidates time_offset, sensor_bandwidth, scale_factor) and, where it names the
low-pass from the motion (`lowpass_choice.choose`), z = (corner - truth) / SE is taken twice: with the profile's
white SE and with that SE times the colour factor (`spectral.colour_factor`, what the workflow reports). Calibrated:
RMS z ~1, ~68 % within 1, ~95 % within 2. `--mocap-noise-scale 0`: an exact mocap (the residual is then the
low-passed gyro noise itself, coloured like the motion the corner is read from).
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).parent))
import generate  # noqa: E402  (beside this script)

from gyrodenoise.atomic import write_json, write_text  # noqa: E402
from gyrodenoise.discrepancy.compare import load_fit_context  # noqa: E402
from gyrodenoise.discrepancy.rank import select_effects  # noqa: E402

TRIALS = {"sensor_lowpass_40hz": 40.0, "sensor_lowpass_25hz": 25.0}
BASE = ["bias", "white_noise", "bias_random_walk"]
CANDIDATES = ["time_offset", "sensor_bandwidth", "scale_factor"]
N_FIT, DURATION_S = 3, 60.0


def one_draw(trial: str, seed: int, work: Path) -> dict:
    root = work / f"{trial}_{seed}"
    generate.make_trial(root, trial, N_FIT, DURATION_S, seed)
    fcs = [load_fit_context(root, f"seq{i:02d}") for i in range(N_FIT)]
    sel = select_effects(fcs, base=BASE, candidates=CANDIDATES)
    d = sel.delay_or_lowpass or {}
    row = {"trial": trial, "seed": seed, "named": list(sel.named), "kept": d.get("kept")}
    if "lowpass_corner_hz" in d:
        truth = TRIALS[trial]
        c = d["lowpass_corner_hz"]
        row |= {
            "corner_hz": c,
            "se_hz": d["lowpass_corner_se_hz"],
            "se_white_hz": d["lowpass_corner_se_white_hz"],
            "colour_factor": d["lowpass_corner_se_colour_factor"],
            "z": (c - truth) / d["lowpass_corner_se_hz"],
            "z_white": (c - truth) / d["lowpass_corner_se_white_hz"],
        }
    return row


def calibration(z: np.ndarray) -> str:
    return (
        f"RMS z {np.sqrt(np.mean(z**2)):.2f}, mean z {np.mean(z):+.2f} ± {np.std(z, ddof=1) / np.sqrt(len(z)):.2f}, "
        f"{np.mean(np.abs(z) < 1):.0%} within 1, {np.mean(np.abs(z) < 2):.0%} within 2"
    )


def draw_args(doc: str, draws: int, first_seed: int, argv: list[str] | None) -> argparse.Namespace:
    """The fresh-draw scripts' options (draws, first seed, mocap noise, output stem); the generator's mocap noise is
    scaled here, before any draw."""
    ap = argparse.ArgumentParser(description=doc.splitlines()[0])
    ap.add_argument("--draws", type=int, default=draws)
    ap.add_argument("--first-seed", type=int, default=first_seed, help="generator seeds first-seed + k (fresh)")
    ap.add_argument("--mocap-noise-scale", type=float, default=1.0, help="the mocap's noise x this (0: exact)")
    ap.add_argument("--out", type=Path, help="results stem (.md, .json); default: print only")
    a = ap.parse_args(argv)
    for k in ("mocap_pos_noise_m", "mocap_rot_noise_deg"):
        generate.BASELINE[k] *= a.mocap_noise_scale
    return a


def write_results(out: Path | None, lines: list[str], record: dict) -> None:
    """Print the table; with an output stem, write it (.md) and the runs (.json), each atomically."""
    text = "\n".join(lines) + "\n"
    print(text)
    if out:
        write_json(out.with_suffix(".json"), record)
        write_text(out.with_suffix(".md"), text)


def main(argv: list[str] | None = None) -> int:
    a = draw_args(__doc__, 40, 5000, argv)
    t0 = time.time()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for trial in TRIALS:
            for k in range(a.draws):
                rows.append(one_draw(trial, a.first_seed + k, Path(tmp)))
                print(rows[-1], flush=True)
    wall = time.time() - t0
    args = sys.argv[1:] if argv is None else argv
    cmd = "python benchmarks/blind_discrepancy/corner_se_calibration.py " + " ".join(args)
    machine = f"{platform.node()} ({platform.machine()}, {os.cpu_count()} CPU threads, OMP_NUM_THREADS=1)"
    lines = [
        "# The low-pass corner's standard error over fresh draws of the blind generator",
        "",
        f"`{cmd}` ({wall:.0f} s, {machine}). Mocap noise x {a.mocap_noise_scale:g}; "
        f"{a.draws} generator seeds from {a.first_seed} per trial, 3 x 60 s fitted, the selection in-process.",
        "",
        "| trial | low-pass named from the motion | white SE: calibration | reported SE (x colour factor) | "
        "colour factor (median) |",
        "|---|---|---|---|---|",
    ]
    for trial in TRIALS:
        got = [r for r in rows if r["trial"] == trial and "z" in r]
        if not got:
            lines.append(f"| {trial} | 0 of {a.draws} | - | - | - |")
            continue
        z, zw = np.array([r["z"] for r in got]), np.array([r["z_white"] for r in got])
        lines.append(
            f"| {trial} | {sum(r['kept'] == 'sensor_bandwidth' for r in got)} of {a.draws} | {calibration(zw)} | "
            f"{calibration(z)} | {np.median([r['colour_factor'] for r in got]):.2f} |"
        )
    lines += ["", "Calibrated: RMS z ~1, ~68 % within 1, ~95 % within 2, mean z ~0."]
    write_results(a.out, lines, {"command": cmd, "machine": machine, "wall_s": wall, "rows": rows})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
