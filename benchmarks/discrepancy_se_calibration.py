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
    return {"effect": effect, "seed": seed, "named": True, **_z(sel, effect, case.param, true)}


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
            row |= _z(sel, effect, param, np.ravel(_truth_value(truth, effect, param)))
        out.append(row)
    return out


def _z(sel, effect: str, param: str, true: np.ndarray) -> dict:
    """z with the standard errors as reported (scaled by the held-out transfer check) and as the fit gave them."""
    est, se = np.ravel(sel.params[effect][param]), np.ravel(sel.se[effect][param])
    transfer = sel.transfer.get(effect, {})
    raw = se / transfer.get("se_factor", 1.0)
    return {
        "true": true.tolist(),
        "estimate": est.tolist(),
        "se": se.tolist(),
        "z": ((est - true) / se).tolist(),
        "z_raw": ((est - true) / raw).tolist(),
        "transfer": transfer,
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--null-draws", type=int, default=10)
    ap.add_argument("--first-seed", type=int, default=0, help="seeds 2000+K.. (replay) and 3000+K.. (procedural)")
    args = ap.parse_args()
    t0 = time.perf_counter()
    runs = [z_scores(e, 2000 + args.first_seed + s, args.null_draws) for e in CASES for s in range(args.seeds)]
    runs += [
        r
        for c in PROCEDURAL
        for s in range(args.seeds)
        for r in procedural_z_scores(c, 3000 + args.first_seed + s, args.null_draws)
    ]
    wall = time.perf_counter() - t0
    rows, pooled = [], {"replay": [], "procedural": []}
    labels = [*(f"{e}" for e in CASES), *dict.fromkeys(r["effect"] for r in runs if "procedural" in r["effect"])]
    for label in labels:
        mine = [r for r in runs if r["effect"] == label and r["named"]]
        pooled["procedural" if "procedural" in label else "replay"] += mine
        shown = f"{label} ({WORLD_CASES[label].specs[0]}, EuRoC replay)" if label in WORLD_CASES else label
        total = sum(r["effect"] == label for r in runs)
        rows.append(_row(shown, mine, f"{len(mine)}/{total}"))
    for world, mine in pooled.items():
        rows.append(_row(f"**pooled, {world}**", mine, ""))
    command = f"python benchmarks/discrepancy_se_calibration.py --seeds {args.seeds} --null-draws {args.null_draws}"
    command += f" --first-seed {args.first_seed}" if args.first_seed else ""
    md = [
        "# Are the discrepancy workflow's standard errors calibrated? (independent test world)",
        "",
        f"`{command}` on {machine_description()}, {wall:.0f} s. z = (estimate - truth) / standard error per "
        "coefficient of the named effect; calibrated: RMS z ~ 1, 68% of |z| < 1, 95% of |z| < 2. Each cell: the "
        "regression's standard errors (raw) / the same scaled by the held-out transfer check, as reported "
        "(`gyrodenoise.discrepancy.transfer`: the Birge ratio of the fit and held-out estimates, never below 1).",
        "",
        "| hidden effect | named | coefficients | RMS z | share abs z < 1 | share abs z < 2 | SE factors |",
        "|---|---|---|---|---|---|---|",
        *rows,
        "",
    ]
    out = OUT.with_name(f"{OUT.name}_from{args.first_seed}") if args.first_seed else OUT
    write_text(out.with_suffix(".md"), "\n".join(md))
    write_json(out.with_suffix(".json"), {"machine": machine_description(), "wall_s": wall, "runs": runs})
    print("\n".join(md))
    return 0


def _row(label: str, runs: list[dict], named: str) -> str:
    if not runs:
        return f"| {label} | {named} | 0 | - | - | - | - |"
    raw, scaled = (np.concatenate([r[key] for r in runs]) for key in ("z_raw", "z"))
    factors = [r["transfer"].get("se_factor", 1.0) for r in runs]

    def both(f) -> str:
        return f"{f(raw)} / {f(scaled)}"

    return (
        f"| {label} | {named} | {len(raw)} | {both(lambda z: f'{np.sqrt(np.mean(z**2)):.2f}')} | "
        f"{both(lambda z: f'{np.mean(np.abs(z) < 1):.0%}')} | {both(lambda z: f'{np.mean(np.abs(z) < 2):.0%}')} | "
        f"{min(factors):.2f}-{max(factors):.2f} |"
    )


if __name__ == "__main__":
    raise SystemExit(main())
