"""How much do the tables' AOE figures depend on the one ground-truth sample every estimate is aligned at?

    python benchmarks/alignment_sensitivity.py

Every AOE of `evaluate` aligns the open-loop estimate on ground truth at the first sample of the scored part (the
paper's "aligned at the first instant"). Ground truth and gyro disagree by a little at any instant, so that choice
carries an error of its own. Here each part is scored again with the alignment (and the scoring) starting later,
by the offsets below; the networks are run on the whole part as `evaluate` runs them (their output does not
change, only where the integration starts). Parts: EuRoC's five test flights (V1_01 against the recomputed ground
truth) and TUM-VI's three validation parts `[50s:]` (the only TUM-VI figures this project has). A method's ranking
that flips within these offsets is not told apart by the tables. Writes --out .md and .json. CPU only; ~1 min.
"""

from __future__ import annotations

import argparse
import math
import platform
import time
from pathlib import Path

import hydra
import numpy as np

from gyrodenoise.atomic import write_json, write_text
from gyrodenoise.config import compose_config
from gyrodenoise.data.sequence import Sequence
from gyrodenoise.metrics import aoe
from gyrodenoise.models.denoiser import predict_gyro
from gyrodenoise.pretrained import load_model
from gyrodenoise.so3 import integrate_gyro
from gyrodenoise.tables import markdown_table

OFFSETS_S = {
    "euroc": (0.0, 0.025, 0.05, 0.1, 0.15, 0.2, 0.5, 1.0),
    "tumvi": (0.0, 0.025, 0.05, 0.1, 0.15, 0.2),
}
MODELS = {
    "euroc": ("euroc-calibrated", "euroc"),
    "tumvi": ("tumvi-calibrated", "tumvi-denoiser", "tumvi"),
}


def parts(dataset: str) -> list[Sequence]:
    """The scored parts, as `evaluate dataset=euroc` (test) and `evaluate dataset=tumvi split=val` read them."""
    overrides = [f"dataset={dataset}"] + (["test=false"] if dataset == "tumvi" else [])
    dm = hydra.utils.instantiate(compose_config("train", overrides).dataset)
    if dataset == "euroc":
        dm.setup("test")
        return list(dm.test_part)
    dm.setup("fit")
    return list(dm.val_part)


def aoe_from(seq: Sequence, gyro: np.ndarray, offset_s: float) -> float:
    """AOE 3D (deg) of the estimate aligned at the first sample with ground truth `offset_s` after the part's start,
    scored from there on."""
    k = int(np.searchsorted(seq.t, seq.t[0] + offset_s - 1e-9))
    k += int(np.argmax(seq.gt_mask[k:]))  # a start inside a ground-truth gap moves to its end
    R = integrate_gyro(seq.rot[k], gyro[k:], seq.dt[k:])
    return math.degrees(aoe(seq.rot[k:], R, seq.gt_mask[k:])[0])


def measure(dataset: str) -> list[dict]:
    models = {name: load_model(name)[0] for name in MODELS[dataset]}
    rows = []
    for seq in parts(dataset):
        gyros = {"raw IMU": seq.gyro, **{n: predict_gyro(m, seq.imu).numpy() for n, m in models.items()}}
        for method, gyro in gyros.items():
            rows.append(
                {
                    "dataset": dataset,
                    "part": seq.name,
                    "method": method,
                    "aoe_deg": {f"{o:g}": aoe_from(seq, gyro, o) for o in OFFSETS_S[dataset]},
                }
            )
            print(dataset, seq.name, method, " ".join(f"{v:.2f}" for v in rows[-1]["aoe_deg"].values()), flush=True)
    return rows


def averages(rows: list[dict]) -> list[dict]:
    out = []
    for dataset, method in dict.fromkeys((r["dataset"], r["method"]) for r in rows):
        sel = [r["aoe_deg"] for r in rows if (r["dataset"], r["method"]) == (dataset, method)]
        mean = {o: float(np.mean([s[o] for s in sel])) for o in sel[0]}
        out.append({"dataset": dataset, "method": method, "parts": len(sel), "mean_aoe_deg": mean})
    return out


def report(result: dict) -> str:
    lines = [
        "# AOE against the alignment sample\n",
        f"`{result['command']}`; {result['machine']}; {result['wall_s']:.0f} s. Each figure: AOE 3D (deg) with the "
        "estimate aligned on ground truth that many seconds after the part's first sample and scored from there "
        "(offset 0: the tables' figure).\n",
    ]
    for dataset in OFFSETS_S:
        offsets = [f"{o:g}" for o in OFFSETS_S[dataset]]
        header = ["part", "method", *[f"+{o} s" for o in offsets], "range"]
        body = []
        for r in [*[r for r in result["rows"] if r["dataset"] == dataset], *averages(result["rows"])]:
            if r["dataset"] != dataset:
                continue
            values = r.get("aoe_deg") or r["mean_aoe_deg"]
            part = r.get("part") or f"**average of {r['parts']}**"
            spread = np.ptp(list(values.values()))
            body.append([part, r["method"], *[f"{values[o]:.2f}" for o in offsets], f"{spread:.2f}"])
        what = "test flights" if dataset == "euroc" else "validation parts [50s:]"
        lines += [f"\n## {dataset}, {what}\n", markdown_table(header, body)]
    return "\n".join(lines) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", type=Path, default=Path("benchmarks/results/alignment_sensitivity"))
    args = ap.parse_args()
    start = time.time()
    rows = [row for dataset in OFFSETS_S for row in measure(dataset)]
    result = {
        "command": "python benchmarks/alignment_sensitivity.py",
        "machine": f"{platform.node()} ({platform.machine()}, CPU)",
        "wall_s": time.time() - start,
        "offsets_s": OFFSETS_S,
        "rows": rows,
        "averages": averages(rows),
    }
    write_json(args.out.with_suffix(".json"), result)
    write_text(args.out.with_suffix(".md"), report(result))


if __name__ == "__main__":
    main()
