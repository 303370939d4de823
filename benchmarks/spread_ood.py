"""Does the ensemble's spread tell a recording unlike its training data? The check of `gyrodenoise.spread_check`.

    python benchmarks/spread_ood.py --model euroc --out benchmarks/results/spread_ood

For the shipped `euroc` ensemble (its file records the spread reference on its training flights): the ratio of
each recording's median spread to that reference, and that of its worst 10-s stretch (`spread_ratio_worst_window`
of `correct` and `evaluate`), whether the check fires (either ratio > SPREAD_RATIO_LIMIT), and the
AOE 3D of the ensemble and of the raw gyro where the ground truth still applies. Recordings: EuRoC training and
test flights as recorded; TUM-VI rooms 1, 3, 5 (another IMU, a BMI160, real data); and the EuRoC test flights with
a user's mistake or another setup applied: gyro in deg/s, accelerometer in g, every second sample (100 Hz
given to a 200-Hz model), the IMU mounted turned 90 deg about its x axis (truth turned with it), and a gyro bias of
0.5 deg/s on every axis. Writes OUT.md and OUT.json. CPU only.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from pathlib import Path

import hydra
import numpy as np
from scipy.spatial.transform import Rotation

from gyrodenoise.atomic import write_json, write_text
from gyrodenoise.config import compose_config
from gyrodenoise.metrics import aoe
from gyrodenoise.models.ensemble import predict_with_spread
from gyrodenoise.pretrained import load_model
from gyrodenoise.provenance import machine_description
from gyrodenoise.so3 import integrate_gyro
from gyrodenoise.spread_check import SPREAD_RATIO_LIMIT, WINDOW_S, spread_ratio, worst_window
from gyrodenoise.tables import markdown_table

TURN = Rotation.from_euler("x", 90, degrees=True).as_matrix()  # body of the turned IMU -> original body
# (imu (N, 6), rot (N, 3, 3), dt (N,)) -> the same with the variant applied; rot None: the truth no longer applies
Variant = Callable[[np.ndarray, np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray | None, np.ndarray]]


def _every_second(imu: np.ndarray, rot: np.ndarray, dt: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    t = np.cumsum(np.r_[0.0, dt[1:]])[::2]
    return imu[::2], rot[::2], np.r_[dt[0], np.diff(t)]


VARIANTS: dict[str, Variant] = {
    "as recorded": lambda imu, rot, dt: (imu, rot, dt),
    "gyro in deg/s": lambda imu, rot, dt: (np.c_[np.degrees(imu[:, :3]), imu[:, 3:]], None, dt),
    "accelerometer in g": lambda imu, rot, dt: (np.c_[imu[:, :3], imu[:, 3:] / 9.80665], None, dt),
    "100 Hz (every 2nd sample)": lambda imu, rot, dt: _every_second(imu, rot, dt),
    "IMU turned 90 deg about x": lambda imu, rot, dt: (np.c_[imu[:, :3] @ TURN, imu[:, 3:] @ TURN], rot @ TURN, dt),
    "gyro bias +0.5 deg/s": lambda imu, rot, dt: (np.c_[imu[:, :3] + np.radians(0.5), imu[:, 3:]], rot, dt),
}


def score(model, meta: dict, imu: np.ndarray, rot: np.ndarray | None, dt: np.ndarray, mask: np.ndarray) -> dict:
    gyro, std = predict_with_spread(model, imu)
    window = worst_window(std, meta, 1.0 / float(np.median(dt[1:])))  # the rate as `evaluate` gives it
    out = {"spread_ratio": spread_ratio(std, meta), "worst_window_ratio": window[0], "worst_window_start_s": window[1]}
    if rot is not None:
        for name, g in (("aoe_ensemble_deg", gyro), ("aoe_raw_deg", imu[:, :3])):
            out[name] = float(np.degrees(aoe(rot, integrate_gyro(rot[0], g, dt), mask)[0]))
    return out


def _range(rows: list[dict], dataset: str, key: str = "spread_ratio") -> str:
    v = [r[key] for r in rows if r["dataset"] == dataset and r["variant"] == "as recorded"]
    return f"{min(v):.2f}-{max(v):.2f}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--model", default="euroc", help="ensemble with a spread reference (default: %(default)s)")
    ap.add_argument("--out", type=Path, default=Path("benchmarks/results/spread_ood"))
    args = ap.parse_args()
    start = time.time()
    model, meta = load_model(args.model)
    if not meta.get("spread_reference"):
        raise SystemExit(f"{args.model}: no spread reference; add one with `python -m gyrodenoise.ensemble reference`")
    rows = []
    for dataset in ("euroc", "tumvi"):
        dm = hydra.utils.instantiate(compose_config("train", [f"dataset={dataset}"]).dataset)
        names = [*dm.train_names, *dm.test_names] if dataset == "euroc" else list(dm.train_names)
        for name in names:
            seq = dm.load(name)
            role = "training flight" if dataset == "euroc" and name in dm.train_names else "test flight"
            role = role if dataset == "euroc" else "another IMU (BMI160)"
            variants = VARIANTS if role == "test flight" else {"as recorded": VARIANTS["as recorded"]}
            for variant, apply in variants.items():
                imu, rot, dt = apply(seq.imu, seq.rot, seq.dt)
                mask = seq.gt_mask[::2] if len(imu) < len(seq.imu) else seq.gt_mask
                r = score(model, meta, imu, rot, dt, mask)
                rows.append({"dataset": dataset, "recording": name, "role": role, "variant": variant, **r})
                print(rows[-1], flush=True)
    table = [
        [
            r["recording"],
            r["role"],
            r["variant"],
            f"{r['spread_ratio']:.2f}",
            f"{r['worst_window_ratio']:.2f} ({r['worst_window_start_s']:.0f} s)",
            "**yes**" if max(r["spread_ratio"], r["worst_window_ratio"]) > SPREAD_RATIO_LIMIT else "no",
            f"{r['aoe_ensemble_deg']:.2f}" if "aoe_ensemble_deg" in r else "-",
            f"{r['aoe_raw_deg']:.2f}" if "aoe_raw_deg" in r else "-",
        ]
        for r in rows
    ]
    groups = {}
    for r in rows:
        groups.setdefault((r["role"], r["variant"]), []).append((r["spread_ratio"], r["worst_window_ratio"]))
    summary = [
        [
            role,
            variant,
            f"{min(x for x, _ in v):.2f}-{max(x for x, _ in v):.2f}",
            f"{min(w for _, w in v):.2f}-{max(w for _, w in v):.2f}",
            f"{sum(max(x, w) > SPREAD_RATIO_LIMIT for x, w in v)} of {len(v)}",
        ]
        for (role, variant), v in groups.items()
    ]
    ref = meta["spread_reference"]
    md = [
        f"# Does the spread of `{meta.get('name', args.model)}` tell a recording unlike its training data?",
        "",
        f"`python benchmarks/spread_ood.py --model {args.model} --out {args.out}` ({machine_description()}, "
        f"{time.time() - start:.0f} s).",
        "",
        f"Reference: {np.degrees(ref['reference_rad_s']):.3f} deg/s, the largest median spread over the training "
        f"flights ({ref['statistic']}; recorded by `{ref['command']}`). The check in `correct` and `evaluate` "
        f"warns when a recording's ratio to it is above {SPREAD_RATIO_LIMIT:g}. That limit was set from the first "
        f"rows measured (EuRoC flights as recorded: {_range(rows, 'euroc')}; TUM-VI rooms: {_range(rows, 'tumvi')}), "
        "before the other variants were computed. The check also judges each recording's worst "
        f"{WINDOW_S:g}-s stretch (`spread_ratio_worst_window`: the largest median over {WINDOW_S:g}-s windows "
        "overlapping by half, `gyrodenoise.spread_check.worst_window`; EuRoC flights as recorded: "
        f"{_range(rows, 'euroc', 'worst_window_ratio')}; added after the limit was set); it fires when either is "
        "above the limit.",
        "",
        markdown_table(
            ["recordings", "variant", "ratio to reference", f"worst {WINDOW_S:g}-s window", "check fires"], summary
        ),
        "",
        "Every recording (AOE 3D in deg, where the ground truth still applies; V1_01 against the dataset's "
        "configured truth):",
        "",
        markdown_table(
            ["recording", "role", "variant", "ratio", "worst window (start)", "fires", "AOE ensemble", "AOE raw gyro"],
            table,
        ),
        "",
    ]
    write_text(args.out.with_suffix(".md"), "\n".join(md))
    write_json(args.out.with_suffix(".json"), {"model": args.model, "limit": SPREAD_RATIO_LIMIT, "rows": rows})
    print("\n".join(md[:12]))


if __name__ == "__main__":
    main()
