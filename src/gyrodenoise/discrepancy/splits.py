"""The discrepancy workflow on every leave-one-out split of a set of sequences, and what all splits agree on.

    python -m gyrodenoise.discrepancy.splits --sequences V1_02_medium V2_03_difficult --out DIR \\
        --root ../shared/data/euroc --gyro-noise-density 1.6968e-4

One verdict depends on which sequences were fitted and which held out: an effect fitted on one flight may not
transfer to another. Each sequence is held out once, the others are fitted (`python -m gyrodenoise.discrepancy`
with every other option passed through); DIR/<held-out>/ holds each split's report, DIR/summary.md the table of
verdicts and gaps and the effects named in every split.
"""

from __future__ import annotations

# ruff: noqa: E402
# (the imports follow the hand-over below)
if __name__ == "__main__":  # python -m gyrodenoise.discrepancy.splits: a Ctrl-C in the imports below is one line
    from gyrodenoise.launch import run_as_main

    run_as_main("discrepancy.splits")  # imports this module as gyrodenoise.discrepancy.splits and runs its main

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from gyrodenoise.atomic import output_path_problem, write_text
from gyrodenoise.discrepancy.__main__ import main as discrepancy_main
from gyrodenoise.discrepancy.__main__ import parse_args as discrepancy_args
from gyrodenoise.launch import PYTHON_M
from gyrodenoise.notices import interrupt_in_one_line
from gyrodenoise.paths import portable_command

PROG = PYTHON_M["discrepancy.splits"]  # as the command is typed


def parse_args(argv: list[str] | None) -> tuple[argparse.Namespace, list[str], tuple[Any, dict] | None]:
    """The splits' options, the options passed on (checked), and the `--network` model loaded for all the runs."""
    p = argparse.ArgumentParser(
        prog=PROG,
        description=__doc__.split("\n")[0],
        epilog="every other option is passed to each split's run: python -m gyrodenoise.discrepancy --help",
    )
    p.add_argument("--sequences", nargs="+", required=True, metavar="NAME", help="at least 2; each is held out once")
    p.add_argument("--out", type=Path, required=True, metavar="DIR", help="one folder per split and summary.md")
    args, rest = p.parse_known_args(argv)
    if len(set(args.sequences)) < 2:
        p.error("--sequences needs at least 2 different sequences (one is fitted while the other is held out)")
    if twice := sorted({n for n in args.sequences if args.sequences.count(n) > 1}):  # its split would run twice
        p.error(f"--sequences names {', '.join(twice)} more than once: give each sequence once")
    clash = [a for a in rest if a.split("=")[0] in ("--fit", "--holdout")]
    if clash:
        p.error(f"{clash[0]}: the splits choose the fitted and held-out sequences; give --sequences only")
    if problem := output_path_problem(args.out, folder=True):
        p.error(f"--out {args.out}: {problem}")
    # the options passed on, checked now as the first split reads them, and said under this command's name and usage
    # (in the first split's run they were `python -m gyrodenoise.discrepancy`'s, whose usage asks for --fit)
    held, *fit = args.sequences
    checked = discrepancy_args([*rest, "--fit", *fit, "--holdout", held, "--out", str(args.out / held)], error=p.error)
    return args, rest, checked.network_model


SUMMARY_FILES = ("summary.json", "summary.md")
GAPS = ("residual_rms_rad_s", "drift_10s_median_deg", "allan_gap_log10", "psd_gap_log10")


def run_splits(
    sequences: list[str], out: Path, passthrough: list[str], network_model: tuple[Any, dict] | None = None
) -> list[dict]:
    """Run the workflow once per held-out sequence; returns the per-split summaries. `network_model`: the
    `--network` model, loaded once (None: each run loads what its options name)."""
    rows = []
    for held in sequences:
        fit = [s for s in sequences if s != held]
        argv = [*passthrough, "--fit", *fit, "--holdout", held, "--out", str(out / held)]
        code = discrepancy_main(argv, network_model=network_model)
        if code == 130:  # Ctrl-C: the split's run has said it in its line; the others are not run
            raise SystemExit(130)
        if code:  # its error is above; the other splits' verdicts would not be the same workflow's
            print(f"error: the split with {held} held out failed (above): the splits stop here", file=sys.stderr)
            raise SystemExit(code)
        if not rows:  # the first split's report is replaced: an earlier run's summary no longer describes the folder
            for name in SUMMARY_FILES:
                (out / name).unlink(missing_ok=True)
        report = json.loads((out / held / "report.json").read_text())
        named = [e["name"] for e in report["named_effects"]]
        tf = report.get("truth_followed") or {}
        rows.append(
            {
                "held_out": held,
                "fit": fit,
                "verdict": report["verdict"],
                "named": named,
                "decided": tf.get("decided", True),
                "below_practical": [c["effect"] for c in report.get("below_practical") or []],
                "gap_before": {k: report["gap_before"][k] for k in GAPS},
                "gap_after": {k: report["gap_after"][k] for k in GAPS},
                "wall_time_s": report["wall_time_s"],
                "machine": report["machine"],
                "code": report.get("code"),
            }
        )
    return rows


def agreement(rows: list[dict]) -> dict:
    """Effects named in every split (all of them decided), in some, and the splits that could not decide."""
    sets = [set(r["named"]) for r in rows]
    every = set.intersection(*sets)  # an undecided split names truth-free effects only
    return {
        "named_in_every_split": sorted(every),
        "named_in_some_splits": sorted(set.union(*sets) - every),
        "undecided_splits": [r["held_out"] for r in rows if not r["decided"]],
    }


def summary_md(rows: list[dict], agree: dict, command: str) -> str:
    code = f"; {rows[0]['code']}" if rows[0].get("code") else ""
    lines = [
        "# The discrepancy workflow over leave-one-out splits",
        "",
        f"`{command}` ({rows[0]['machine']}{code}; per split's wall time in the table).",
        "",
        "| held out | fitted | verdict | residual RMS (rad/s) | 10-s drift (deg) | Allan gap | spectral gap "
        "| wall (s) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        b, a = r["gap_before"], r["gap_after"]
        cells = [f"{b[k]:.4g} -> {a[k]:.4g}" for k in GAPS]
        lines.append(
            f"| [{r['held_out']}]({r['held_out']}/report.md) | {', '.join(r['fit'])} | {r['verdict']} | "
            + " | ".join(cells)
            + f" | {r['wall_time_s']:.0f} |"
        )
    every = ", ".join(agree["named_in_every_split"]) or "nothing"
    some = ", ".join(agree["named_in_some_splits"]) or "nothing"
    lines += ["", f"Named in every split: **{every}**. Named in some splits only: {some}."]
    if agree["undecided_splits"]:
        lines.append(
            f"Splits whose ground truth cannot decide the effects judged against it (held out: "
            f"{', '.join(agree['undecided_splits'])}): only effects read off the gyro's own values can be named in "
            "every split."
        )
    lines += [
        "",
        "An effect named in one split only was fitted on some sequences and transferred to the one held out, but not "
        "the other way round: it is not a property of the sensor that these sequences agree on.",
    ]
    return "\n".join(lines) + "\n"


@interrupt_in_one_line
def main(argv: list[str] | None = None) -> int:
    args, rest, network_model = parse_args(argv)
    rows = run_splits(args.sequences, args.out, rest, network_model)
    agree = agreement(rows)
    command = f"{PROG} " + portable_command(sys.argv[1:] if argv is None else argv)
    summary = {"command": command, "splits": rows, **agree}
    write_text(args.out / "summary.json", json.dumps(summary, indent=2) + "\n")
    write_text(args.out / "summary.md", summary_md(rows, agree, command))
    print(f"named in every split: {', '.join(agree['named_in_every_split']) or 'nothing'}; summary: {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
