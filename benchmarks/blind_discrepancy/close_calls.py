"""How often the delay-or-low-pass choice goes wrong on its close calls (blind generator, many seeds).

A 4 ms time offset and a 40 Hz first-order low-pass delay the motion alike; behind the generator's 0.05 deg mocap
their expected delta BIC against each other is ~13-31 at these sizes. This draws both trials on fresh seeds at two
sizes (2 fitted sequences of 40 s, as the tests; 3 of 60 s, as the blind runner) and runs the selection in process
(`rank.select_effects`, base bias + white noise + bias random walk, candidates time_offset, sensor_bandwidth,
scale_factor; fixed detection threshold 10, no null re-simulations), recording which explanation is kept, its margin
over the switch's threshold (`lowpass_choice.SWITCH_THRESHOLD`, 0; the detection threshold, 10, before session 54),
the charge for smoothing the truth's noise, whether the report cautions (a margin within the statistic's spread,
2 sqrt(expected delta BIC): `Selection.cautions`) and, where the right effect is named, its value's z against its
standard error.

    python benchmarks/blind_discrepancy/close_calls.py [--seeds 300 320] [--work /tmp/close_calls] [--name NAME]

Writes benchmarks/results/blind_close_calls.{md,json}. One process, OMP_NUM_THREADS=1 recommended.
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import generate  # noqa: E402  (this folder's standalone generator)
from run import _git  # noqa: E402

from gyrodenoise.atomic import write_text  # noqa: E402
from gyrodenoise.discrepancy.compare import load_fit_context  # noqa: E402
from gyrodenoise.discrepancy.lowpass_choice import SWITCH_THRESHOLD  # noqa: E402
from gyrodenoise.discrepancy.rank import select_effects  # noqa: E402

RESULTS = Path(__file__).resolve().parents[2] / "benchmarks" / "results"
BASE = ["bias", "white_noise", "bias_random_walk"]
CANDIDATES = ["time_offset", "sensor_bandwidth", "scale_factor"]
TRIALS = {"time_offset": "time_offset", "sensor_lowpass_40hz": "sensor_bandwidth"}  # trial -> the right answer
SIZES = [(2, 40.0), (3, 60.0)]
TRUTH = {"time_offset": ("delta", 4e-3), "sensor_lowpass_40hz": ("corner_hz", 40.0)}  # parameter, SI value


def _z_row(trial: str, size: str, rs: list[dict]) -> str:
    """How well the SE of the right effect's value describes its error, over the seeds where it was named."""
    z = np.array([r["z"] for r in rs if r.get("z") is not None], dtype=float)
    if not len(z):
        return f"| {trial} | {size} | 0 | - | - | - | - | - |"
    se = np.median([r["se"] for r in rs if r.get("z") is not None])
    unit, k = ("ms", 1e3) if TRUTH[trial][0] == "delta" else ("Hz", 1.0)
    return (
        f"| {trial} | {size} | {len(z)} | {np.sqrt(np.mean(z**2)):.2f} | {np.mean(z):+.2f}"
        f" | {np.mean(np.abs(z) < 1):.0%} | {np.mean(np.abs(z) < 2):.0%} | {k * se:.3g} {unit} |"
    )


def one(work: Path, trial: str, n: int, duration: float, seed: int) -> dict:
    root = work / f"{trial}_{n}x{duration:g}_s{seed}"
    generate.make_trial(root, trial, n, duration, seed)
    fcs = [load_fit_context(root, f"seq{i:02d}") for i in range(n)]
    sel = select_effects(fcs, base=BASE, candidates=CANDIDATES)
    d = sel.delay_or_lowpass or {}
    value = TRUTH[trial]  # the right effect's value and the SE the selection gives it, where it is named alone
    est = se = None
    if sel.named == [TRIALS[trial]]:
        est, se = (float(np.ravel(x[value[0]])[0]) for x in (sel.params[TRIALS[trial]], sel.se[TRIALS[trial]]))
    return {
        "trial": trial,
        "size": f"{n} x {duration:g} s",
        "seed": seed,
        "named": sel.named,
        "kept": d.get("kept"),
        "right": sel.named == [TRIALS[trial]],
        "margin": d["delta_bic_lowpass_vs_offset"] - SWITCH_THRESHOLD if "delta_bic_lowpass_vs_offset" in d else None,
        "charge": d.get("truth_error_smoothing_bic"),
        "expected": d.get("expected_delta_bic"),
        "cautioned": bool(sel.cautions),
        "estimate": est,
        "se": se,
        "z": None if est is None or not se else (est - value[1]) / se,
    }


def _summary_row(trial: str, size: str, rs: list[dict]) -> str:
    m = np.array([r["margin"] for r in rs if r["margin"] is not None], dtype=float)

    def med(k: str) -> float:
        return float(np.median([r[k] for r in rs if r[k] is not None]))

    wrong_c = sum(not r["right"] and r["cautioned"] for r in rs)
    wrong_n = sum(not r["right"] and not r["cautioned"] for r in rs)
    right_c = sum(r["right"] and r["cautioned"] for r in rs)
    spread = f"{np.median(m):+.0f} [{m.min():+.0f}, {m.max():+.0f}]" if len(m) else "-"
    return (
        f"| {trial} | {size} | {sum(r['right'] for r in rs)}/{len(rs)} | {wrong_c} | {wrong_n} | {right_c} | {spread}"
        f" | {med('expected'):.0f} | {med('charge'):.0f} |"
    )


def _per_group(rows: list[dict], row_of) -> list[str]:
    """One table row per trial and size: row_of(trial, size, that group's rows)."""
    out = []
    for trial in TRIALS:
        for n, duration in SIZES:
            size = f"{n} x {duration:g} s"
            out.append(row_of(trial, size, [r for r in rows if r["trial"] == trial and r["size"] == size]))
    return out


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, nargs=2, default=[300, 320], metavar=("FIRST", "END"))
    ap.add_argument("--work", type=Path, default=Path("/tmp/close_calls"))
    ap.add_argument("--results", type=Path, default=RESULTS)
    ap.add_argument("--name", default="blind_close_calls", help="results file stem (NAME.md, NAME.json)")
    a = ap.parse_args(argv)
    t0 = time.time()
    rows = []
    for trial in TRIALS:
        for n, duration in SIZES:
            for seed in range(*a.seeds):
                rows.append(one(a.work, trial, n, duration, seed))
                r = rows[-1]
                print(trial, r["size"], seed, r["named"], f"margin {r['margin']}", flush=True)
    wall = time.time() - t0
    lines = [
        "# Delay or low-pass: the close calls over fresh seeds (blind generator)",
        "",
        f"Command: `python benchmarks/blind_discrepancy/close_calls.py --seeds {a.seeds[0]} {a.seeds[1]}"
        f"{'' if a.name == 'blind_close_calls' else ' --name ' + a.name}`  ",
        f"Machine: {platform.node()} ({platform.machine()}), one process; wall time {wall:.0f} s. Code: {_git()}.",
        "",
        "Selection in process, fixed detection threshold 10 (no null re-simulations), candidates time_offset,"
        " sensor_bandwidth, scale_factor. Margin: delta BIC of the low-pass against the offset minus the switch's"
        f" threshold, {SWITCH_THRESHOLD:g} (> 0: low-pass kept),"
        " after the charge for smoothing the truth's noise. Cautioned: the report says the margin is within the"
        " statistic's spread, 2 sqrt(expected delta BIC), so it may be the other explanation.",
        "",
        "| trial | size | right | wrong, cautioned | wrong, not cautioned | right, cautioned |"
        " margin: median [min, max] | expected delta BIC (median) | charge (median) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    lines += _per_group(rows, _summary_row)
    lines += [
        "",
        "Standard errors, where the right effect is named alone: z = (estimate - truth) / SE (a time offset: the"
        " regression's SE; a corner: the motion fit's profile, `lowpass_choice.profile_corner_se`). Calibrated:"
        " RMS z ~1, ~68 % within 1 and ~95 % within 2.",
        "",
        "| trial | size | named | RMS z | mean z | within 1 | within 2 | median SE |",
        "|---|---|---|---|---|---|---|---|",
    ]
    lines += _per_group(rows, _z_row)
    wrong = [r for r in rows if not r["right"]]
    lines += ["", "Wrong answers: " + ("none" if not wrong else "; ".join(
        f"{r['trial']} {r['size']} seed {r['seed']}: named {', '.join(r['named']) or 'nothing'}, margin "
        f"{'-' if r['margin'] is None else format(r['margin'], '+.1f')}"
        f"{', cautioned' if r['cautioned'] else ''}" for r in wrong)), ""]  # fmt: skip
    a.results.mkdir(parents=True, exist_ok=True)
    write_text(a.results / f"{a.name}.md", "\n".join(lines))
    write_text(a.results / f"{a.name}.json", json.dumps({"rows": rows, "wall_time_s": wall}, indent=1))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
