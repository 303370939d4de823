"""Wall time of the discrepancy workflow's effect selection (`rank.select_effects`) on blind-generator data, and the
numbers it gives, so that a change meant only for speed can be checked to leave them alone.

Cases (benchmarks/blind_discrepancy/generate.py, noisy mocap, the generator's baseline sensor model as the base):
- lowpass_10hz: a 10 Hz sensor low-pass, 3 x 60 s, generator seed 11 (the floor refit's dev case: the selection
  runs twice);
- time_offset: IMU stamps 4 ms late, 2 x 40 s, seed 3 (the delay-or-low-pass test's case).

    python benchmarks/discrepancy_selection_speed.py --out benchmarks/results/discrepancy_selection_speed_after.json
    python benchmarks/discrepancy_selection_speed.py --out ... --compare benchmarks/results/..._before.json

Run it on an older commit with that commit's package first on the path (PYTHONPATH=<worktree>/src). `--compare`
reports whether every number (named effects, parameters, SEs, the delay-or-low-pass figures) is bit-identical, and
where not, whether anything but the numbers differs and the largest relative difference of a number.
OMP_NUM_THREADS caps the threads (numpy, the FFTs)."""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent / "blind_discrepancy"))
import generate  # noqa: E402  (the standalone generator)

from gyrodenoise.atomic import write_json, write_text  # noqa: E402
from gyrodenoise.discrepancy.compare import load_fit_context  # noqa: E402
from gyrodenoise.discrepancy.rank import select_effects  # noqa: E402
from gyrodenoise.provenance import git_revision, machine_description  # noqa: E402

BASE = ["bias", "white_noise", "bias_random_walk"]
CANDIDATES = ["time_offset", "sensor_bandwidth", "scale_factor"]
CASES = {  # name -> (trial, hidden effect added to TRIALS or None, sequences, seconds each, generator seed)
    "lowpass_10hz": ("lowpass_10hz", generate.HiddenEffect("sensor_lowpass", {"corner_hz": 10.0}), 3, 60.0, 11),
    "time_offset": ("time_offset", None, 2, 40.0, 3),
}


def numbers(sel) -> dict:
    """Everything the selection reports that a speed-only change must leave alone."""
    arr = {k: {p: np.asarray(v).tolist() for p, v in d.items()} for k, d in sel.params.items()}
    se = {k: {p: np.asarray(v).tolist() for p, v in d.items()} for k, d in sel.se.items()}
    dol = {k: v for k, v in (sel.delay_or_lowpass or {}).items() if isinstance(v, (bool, int, float, str))}
    return {"named": list(sel.named), "params": arr, "se": se, "delay_or_lowpass": dol,
            "nuisance_refit": sel.nuisance_refit is not None}  # fmt: skip


def run_case(name: str) -> dict:
    trial, hidden, n, seconds, seed = CASES[name]
    if hidden is not None:
        generate.TRIALS[trial] = hidden
    with tempfile.TemporaryDirectory() as tmp:
        generate.make_trial(Path(tmp), trial, n, seconds, seed)
        t0 = time.perf_counter()
        fcs = [load_fit_context(Path(tmp), f"seq{i:02d}") for i in range(n)]
        t1 = time.perf_counter()
        sel = select_effects(fcs, base=BASE, candidates=CANDIDATES)
        t2 = time.perf_counter()
    return {"load_s": t1 - t0, "select_s": t2 - t1, "numbers": numbers(sel)}


def _commit(folder: Path) -> str:
    """The commit of the checkout the package was imported from (+ "-dirty" when its src/ differs from it)."""
    rev = git_revision(folder, scope=".")
    return "unknown" if rev is None else rev[0] + ("-dirty" if rev[1] else "")


def _text(x: object) -> str:
    """x as canonical JSON text: floats by their shortest exact repr, so equal text is equal bits (NaN included)."""
    return json.dumps(json.loads(json.dumps(x, default=float)), sort_keys=True)


def _differences(a: object, b: object, path: str = "") -> tuple[list[str], float, str]:
    """How two results' numbers differ: the paths where anything but a number differs (named effects, decisions,
    structure), and the largest relative difference of a number, with its path."""
    if isinstance(a, dict) and isinstance(b, dict) and set(a) == set(b):
        parts = [_differences(a[k], b[k], f"{path}/{k}") for k in sorted(a)]
    elif isinstance(a, list) and isinstance(b, list) and len(a) == len(b):
        parts = [_differences(x, y, f"{path}[{i}]") for i, (x, y) in enumerate(zip(a, b, strict=True))]
    elif all(isinstance(x, int | float) and not isinstance(x, bool) for x in (a, b)):
        if a == b or (np.isnan(a) and np.isnan(b)):
            return [], 0.0, ""
        return [], abs(a - b) / max(abs(a), abs(b)), path
    else:
        return ([] if _text(a) == _text(b) else [path]), 0.0, ""
    other = [p for part in parts for p in part[0]]
    worst = max(parts, key=lambda part: part[1], default=([], 0.0, ""))
    return other, worst[1], worst[2]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", type=Path, required=True, help="result JSON (a .md beside it)")
    ap.add_argument("--compare", type=Path, help="an earlier result: are the numbers bit-identical?")
    ap.add_argument("--cases", nargs="+", default=list(CASES), choices=list(CASES))
    args = ap.parse_args()
    import gyrodenoise

    res = {
        "command": "python " + " ".join(sys.argv),
        "package_commit": _commit(Path(gyrodenoise.__file__).parent),
        "machine": machine_description(),
        "omp_num_threads": os.environ.get("OMP_NUM_THREADS"),
        "cases": {name: run_case(name) for name in args.cases},
    }
    lines = [f"# Effect selection: wall time\n\nCommand: `{res['command']}`  \nMachine: {res['machine']}; "
             f"OMP_NUM_THREADS={res['omp_num_threads']}\n", "| case | named | load (s) | selection (s) |",
             "|---|---|---|---|"]  # fmt: skip
    for name, c in res["cases"].items():
        lines.append(f"| {name} | {', '.join(c['numbers']['named'])} | {c['load_s']:.1f} | {c['select_s']:.1f} |")
    if args.compare:
        ref = json.loads(args.compare.read_text())
        cases = [n for n in res["cases"] if n in ref["cases"]]
        same = {n: _text(ref["cases"][n]["numbers"]) == _text(res["cases"][n]["numbers"]) for n in cases}
        diff = {n: _differences(res["cases"][n]["numbers"], ref["cases"][n]["numbers"]) for n in cases}
        res["compared_with"] = {
            "file": str(args.compare),
            "identical_numbers": same,
            "other_than_numbers_differ": {n: d[0] for n, d in diff.items()},
            "largest_relative_difference": {n: {"value": d[1], "where": d[2]} for n, d in diff.items()},
        }
        lines.append(f"\nAgainst `{args.compare}`: numbers bit-identical per case: {same}; selection time")
        for n in same:
            before, after = ref["cases"][n]["select_s"], res["cases"][n]["select_s"]
            other, worst, where = diff[n]
            what = "named effects and every decision the same" if not other else f"DIFFERENT: {', '.join(other)}"
            if not same[n]:
                what += f"; largest relative difference of a number {worst:.1e} ({where})"
            lines.append(f"- {n}: {before:.1f} s -> {after:.1f} s (x{before / after:.2f}); {what}")
    write_json(args.out, res)
    write_text(args.out.with_suffix(".md"), "\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
