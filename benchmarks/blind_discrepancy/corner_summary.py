"""The low-pass corners of blind-trial result files, side by side, with their z against the hidden corner.

    python benchmarks/blind_discrepancy/corner_summary.py --label before OLD1.json OLD2.json \
        --label after NEW1.json NEW2.json [--out results/NAME.md]

Reads the JSON files `run.py` writes (`sensor_lowpass_*` trials only) and prints, per group, each corner with its
standard error and z = (fitted - truth) / SE, then the group's RMS z, how many lie below the truth, the largest |z|
and the chi-square p of sum z^2 (calibrated and unbiased: RMS z ~1, about half below, p uniform).
"""

from __future__ import annotations

import argparse
import json
import re
from pathlib import Path

import numpy as np
from scipy import stats

TRUTH = re.compile(r"sensor_lowpass_(\d+)hz")


def corners(path: Path) -> list[dict]:
    """One row per low-pass trial of a result file: file, trial, truth, corner, SE, z."""
    rows = []
    for t in json.loads(path.read_text())["trials"]:
        m = TRUTH.fullmatch(t["trial"])
        dol = t.get("delay_or_lowpass") or {}
        if m is None or "lowpass_corner_hz" not in dol:
            continue
        truth, c, se = float(m.group(1)), dol["lowpass_corner_hz"], dol["lowpass_corner_se_hz"]
        z = (c - truth) / se
        rows.append({"file": path.stem, "trial": t["trial"], "truth": truth, "corner": c, "se": se, "z": z})
    return rows


def summary(rows: list[dict]) -> str:
    z = np.array([r["z"] for r in rows])
    p = float(stats.chi2.sf(np.sum(z**2), len(z)))
    below = int(np.sum(z < 0))
    return (
        f"{len(z)} corners: RMS z {np.sqrt(np.mean(z**2)):.2f}, {below} below the truth, "
        f"largest |z| {np.max(np.abs(z)):.2f}, chi-square p {p:.3f}"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--label", action="append", nargs="+", metavar=("LABEL", "JSON"), required=True)
    ap.add_argument("--out", type=Path, help="also write the table here (markdown)")
    a = ap.parse_args()
    lines = ["| group | file | trial | truth (Hz) | corner (Hz) | SE (Hz) | z |", "|---|---|---|---|---|---|---|"]
    sums = []
    for label, *files in a.label:
        rows = [r for f in files for r in corners(Path(f))]
        if not rows:
            raise SystemExit(f"{label}: no sensor_lowpass trial with a fitted corner in {files}")
        lines += [
            f"| {label} | {r['file']} | {r['trial']} | {r['truth']:g} | {r['corner']:.4f} | {r['se']:.4f} "
            f"| {r['z']:+.2f} |"
            for r in rows
        ]
        sums.append(f"- {label}: {summary(rows)}")
    text = "\n".join([*lines, "", *sums]) + "\n"
    print(text, end="")
    if a.out:
        tmp = a.out.with_suffix(a.out.suffix + ".tmp")
        tmp.write_text(text)
        tmp.replace(a.out)


if __name__ == "__main__":
    main()
