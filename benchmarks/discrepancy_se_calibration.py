"""Are the discrepancy workflow's standard errors calibrated? z-scores of fitted effects on the independent world.

    python benchmarks/discrepancy_se_calibration.py [--seeds 3] [--null-draws 10]

Two worlds, both the independent test world (`gyrodenoise.testworld`, Vicon-like mocap truth): (1) EuRoC V1_02 /
V2_01 motion replayed, one hidden effect at the small magnitude of `discrepancy.worldcases.WORLD_CASES`, only that
candidate tried; (2) procedural motion (two motion seeds, one sensor) with a consumer-MEMS bias and noise and one or
two hidden effects, every candidate tried as the CLI does. `workflow.decide` fits on one flight (the other held out);
every coefficient of a named checked effect gives z = (estimate - truth) / standard error. Calibrated errors give
RMS z ~ 1 and ~68% of |z| < 1 (95% of |z| < 2).
Writes benchmarks/results/discrepancy_se_calibration.{md,json}. ~1 min per run on the 2-core VM.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from gyrodenoise.atomic import write_json, write_text
from gyrodenoise.discrepancy.compare import load_fit_context
from gyrodenoise.discrepancy.workflow import decide
from gyrodenoise.discrepancy.worldcases import FIT_FLIGHT, HOLDOUT_FLIGHT, WORLD_CASES, _truth_value, make_world
from gyrodenoise.provenance import machine_description
from gyrodenoise.testworld import make_sequence

OUT = Path("benchmarks/results/discrepancy_se_calibration")
CASES = ("scale_factor", "misalignment", "g_sensitivity", "time_offset")
# a user's own sensor on procedural motion, every candidate tried (as the CLI does): two effects hidden at once
SENSOR = "bias=0.5deg/s,white_noise=0.007deg/s/sqrt(Hz)"
PROCEDURAL = {
    "g_sensitivity + time_offset": ("g_sensitivity=0.3deg/s/g,time_offset=3ms", {"g_sensitivity": "matrix"}),
    "scale_factor + g_sensitivity": ("scale_factor=1000ppm,g_sensitivity=0.3deg/s/g", {"scale_factor": "scale"}),
    "misalignment": ("misalignment=2mrad", {"misalignment": "angles"}),
}


def z_scores(effect: str, seed: int, null_draws: int) -> dict:
    case = WORLD_CASES[effect]
    with tempfile.TemporaryDirectory() as root:
        truth = make_world(root, case.specs[0], seed)
        fit, hold = [load_fit_context(root, FIT_FLIGHT)], [load_fit_context(root, HOLDOUT_FLIGHT)]
        _, sel, _ = decide(fit, hold, candidates=[effect], null_draws=null_draws, seed=seed)
    true = np.ravel(_truth_value(truth, effect, case.param))
    if effect not in sel.named:
        return {"effect": effect, "seed": seed, "named": False}
    est = np.ravel(sel.params[effect][case.param])
    se = np.ravel(sel.se[effect][case.param])
    return {
        "effect": effect,
        "seed": seed,
        "named": True,
        "true": true.tolist(),
        "estimate": est.tolist(),
        "se": se.tolist(),
        "z": ((est - true) / se).tolist(),
    }


def procedural_z_scores(case: str, seed: int, null_draws: int) -> list[dict]:
    """The procedural world (testworld --trajectory procedural:1 / :2, one sensor from `seed`, preset none + SENSOR):
    z of the checked effects' coefficients, with all candidates tried."""
    effects, checked = PROCEDURAL[case]
    with tempfile.TemporaryDirectory() as root:
        truth = None
        for k, name in ((1, "fit"), (2, "held_out")):
            seq = make_sequence(root, f"procedural:{k}", f"{SENSOR},{effects}", preset="none", seed=seed, name=name)
            truth = truth or seq.truth
        fit, hold = [load_fit_context(root, "fit")], [load_fit_context(root, "held_out")]
        _, sel, _ = decide(fit, hold, null_draws=null_draws, seed=seed)
    out = []
    for effect, param in checked.items():
        row = {"effect": f"{effect} ({case}, procedural)", "seed": seed, "named": effect in sel.named}
        if row["named"]:
            true = np.ravel(_truth_value(truth, effect, param))
            est, se = np.ravel(sel.params[effect][param]), np.ravel(sel.se[effect][param])
            row |= {
                "true": true.tolist(),
                "estimate": est.tolist(),
                "se": se.tolist(),
                "z": ((est - true) / se).tolist(),
            }
        out.append(row)
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--null-draws", type=int, default=10)
    args = ap.parse_args()
    t0 = time.perf_counter()
    runs = [z_scores(e, 2000 + s, args.null_draws) for e in CASES for s in range(args.seeds)]
    runs += [
        r for c in PROCEDURAL for s in range(args.seeds) for r in procedural_z_scores(c, 3000 + s, args.null_draws)
    ]
    wall = time.perf_counter() - t0
    rows, all_z = [], {"replay": [], "procedural": []}
    labels = [*(f"{e}" for e in CASES), *dict.fromkeys(r["effect"] for r in runs if "procedural" in r["effect"])]
    for label in labels:
        mine = [r for r in runs if r["effect"] == label]
        zs = np.concatenate([r["z"] for r in mine if r["named"]] or [np.zeros(0)])
        all_z["procedural" if "procedural" in label else "replay"].append(zs)
        shown = f"{label} ({WORLD_CASES[label].specs[0]}, EuRoC replay)" if label in WORLD_CASES else label
        rows.append(_row(shown, zs, f"{sum(r['named'] for r in mine)}/{len(mine)}"))
    for world, zs in all_z.items():
        rows.append(_row(f"**pooled, {world}**", np.concatenate(zs), ""))
    md = [
        "# Are the discrepancy workflow's standard errors calibrated? (independent test world)",
        "",
        f"`python benchmarks/discrepancy_se_calibration.py --seeds {args.seeds} --null-draws {args.null_draws}` on "
        f"{machine_description()}, {wall:.0f} s. z = (estimate - truth) / standard error per coefficient of the "
        "named effect; calibrated: RMS z ~ 1, 68% of |z| < 1, 95% of |z| < 2.",
        "",
        "| hidden effect | named | coefficients | RMS z | share abs z < 1 | share abs z < 2 |",
        "|---|---|---|---|---|---|",
        *rows,
        "",
    ]
    write_text(OUT.with_suffix(".md"), "\n".join(md))
    write_json(OUT.with_suffix(".json"), {"machine": machine_description(), "wall_s": wall, "runs": runs})
    print("\n".join(md))
    return 0


def _row(label: str, z: np.ndarray, named: str) -> str:
    if not len(z):
        return f"| {label} | {named} | 0 | - | - | - |"
    a = np.abs(z)
    return (
        f"| {label} | {named} | {len(z)} | {np.sqrt(np.mean(z**2)):.2f} | {np.mean(a < 1):.0%} | {np.mean(a < 2):.0%} |"
    )


if __name__ == "__main__":
    raise SystemExit(main())
