"""Correct EuRoC test sequences through the `gyrodenoise-correct` CLI, batch and streaming engines,
and score the TUM orientation files it writes against the ground truth (AOE, as in the report).

    python benchmarks/correct_euroc.py --model euroc [--sequences MH_02_easy V1_01_easy]

The CLI sees only the IMU file (no ground truth): each sequence's imu0/data.csv is cut to the
ground-truth span (the same samples the evaluation uses) and fed to the CLI; its orientation output
starts at identity and is aligned on the ground truth at the first instant for scoring, as the
evaluation does. Also reported: the evaluation's own path (predict_gyro + integrate_gyro on the
Sequence) and the raw IMU, so the three can be compared. Writes benchmarks/results/correct_euroc.json/.md.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from omegaconf import OmegaConf
from scipy.spatial.transform import Rotation

import gyrodenoise
from gyrodenoise.atomic import write_text
from gyrodenoise.correct import main as correct_main
from gyrodenoise.data.cache import load_sequence
from gyrodenoise.metrics import aoe
from gyrodenoise.models.denoiser import predict_gyro
from gyrodenoise.paths import portable_command
from gyrodenoise.pretrained import load_model
from gyrodenoise.so3 import integrate_gyro

HERE = Path(__file__).resolve().parent
DATA = Path(os.environ.get("GYRODENOISE_DATA", HERE.parents[1] / "shared" / "data"))
CONF = OmegaConf.load(Path(gyrodenoise.__file__).parent / "conf" / "dataset" / "euroc.yaml")


def cut_imu_file(src: Path, dst: Path, t0_ns: int, t1_ns: int) -> None:
    """Copy the header and the lines with t0 <= stamp <= t1, unchanged (same text, same values)."""
    with open(src) as fin, open(dst, "w") as fout:
        for line in fin:
            if line.startswith("#") or not line.strip():
                fout.write(line)
            elif t0_ns <= int(line.split(",", 1)[0]) <= t1_ns:
                fout.write(line)


def read_cli_outputs(folder: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    t_ns = np.loadtxt(folder / "imu_corrected.csv", delimiter=",", dtype=np.int64, usecols=0)
    gyro = np.loadtxt(folder / "imu_corrected.csv", delimiter=",", usecols=(1, 2, 3))
    q = np.loadtxt(folder / "orientation.txt", usecols=(4, 5, 6, 7))
    return t_ns, gyro, Rotation.from_quat(q).as_matrix()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--model", default="euroc")
    ap.add_argument("--sequences", nargs="+", default=list(CONF.test_seqs))
    ap.add_argument("--out", default=str(HERE / "results" / "correct_euroc"))
    args = ap.parse_args()
    model, meta = load_model(args.model)
    rows = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.sequences:
            gt_file = CONF.gt_files.get(name)
            seq = load_sequence(DATA / "euroc", name, gt_file, cache_dir="")
            t_ns = seq.t0_ns + np.round(seq.t * 1e9).astype(np.int64)
            imu_in = Path(tmp) / name / "data.csv"
            imu_in.parent.mkdir(parents=True)
            cut_imu_file(DATA / "euroc" / name / "mav0" / "imu0" / "data.csv", imu_in, t_ns[0], t_ns[-1])
            row = {"samples": len(seq), "gt_file": gt_file or "state_groundtruth_estimate0/data.csv"}
            outs = {}
            for engine in ("batch", "streaming"):
                out = Path(tmp) / name / engine
                t0 = time.perf_counter()
                code = correct_main([str(imu_in), "-m", str(args.model), "-o", str(out), "--engine", engine])
                row[f"cli_{engine}_wall_s"] = round(time.perf_counter() - t0, 2)
                if code != 0:
                    raise SystemExit(f"gyrodenoise-correct failed on {name} ({engine})")
                tc, gyro, R = read_cli_outputs(out)
                if not np.array_equal(tc, t_ns):
                    raise SystemExit(f"{name}: CLI output stamps differ from the sequence's")
                R = seq.rot[0] @ np.swapaxes(R[0], -1, -2) @ R  # align at the first instant
                a3, ayaw = aoe(seq.rot, R, seq.gt_mask)
                row[f"aoe_deg_cli_{engine}"] = round(float(np.degrees(a3)), 3)
                row[f"aoe_yaw_deg_cli_{engine}"] = round(float(np.degrees(ayaw)), 3)
                outs[engine] = (gyro, R)
            row["max_abs_gyro_diff_batch_vs_streaming_rad_s"] = float(
                np.abs(outs["batch"][0] - outs["streaming"][0]).max()
            )
            row["max_orientation_diff_batch_vs_streaming_deg"] = float(
                np.degrees(
                    np.linalg.norm(
                        Rotation.from_matrix(np.swapaxes(outs["batch"][1], -1, -2) @ outs["streaming"][1]).as_rotvec(),
                        axis=1,
                    ).max()
                )
            )
            R_eval = integrate_gyro(seq.rot[0], predict_gyro(model, seq.imu).numpy(), seq.dt)
            R_raw = integrate_gyro(seq.rot[0], seq.gyro, seq.dt)
            row["aoe_deg_evaluation_path"] = round(float(np.degrees(aoe(seq.rot, R_eval, seq.gt_mask)[0])), 3)
            row["aoe_deg_raw_imu"] = round(float(np.degrees(aoe(seq.rot, R_raw, seq.gt_mask)[0])), 3)
            rows[name] = row
            print(name, json.dumps(row), flush=True)
    report = {
        "command": "python " + portable_command(sys.argv),
        "model": meta["name"],
        "model_meta": {k: meta.get(k) for k in ("dataset", "train_seqs", "epoch", "checkpoint") if k in meta},
        "date": time.strftime("%Y-%m-%d %H:%M:%S"),
        "sequences": rows,
        "mean_aoe_deg": {
            k: round(float(np.mean([r[k] for r in rows.values()])), 3)
            for k in ("aoe_deg_cli_batch", "aoe_deg_cli_streaming", "aoe_deg_evaluation_path", "aoe_deg_raw_imu")
        },
    }
    out = Path(args.out)
    write_text(out.with_suffix(".json"), json.dumps(report, indent=2) + "\n")
    write_text(out.with_suffix(".md"), markdown(report))
    print(markdown(report))


def markdown(r: dict) -> str:
    head = (
        "| sequence | AOE CLI batch (deg) | AOE CLI streaming (deg) | AOE evaluation path (deg) | AOE raw IMU (deg) "
        "| max abs gyro diff batch/stream (rad/s) | max orientation diff (deg) |\n|---|---:|---:|---:|---:|---:|---:|\n"
    )
    body = "".join(
        f"| {n} | {v['aoe_deg_cli_batch']} | {v['aoe_deg_cli_streaming']} | {v['aoe_deg_evaluation_path']} | "
        f"{v['aoe_deg_raw_imu']} | {v['max_abs_gyro_diff_batch_vs_streaming_rad_s']:.1e} | "
        f"{v['max_orientation_diff_batch_vs_streaming_deg']:.1e} |\n"
        for n, v in r["sequences"].items()
    )
    m = r["mean_aoe_deg"]
    body += (
        f"| **mean** | {m['aoe_deg_cli_batch']} | {m['aoe_deg_cli_streaming']} | {m['aoe_deg_evaluation_path']} | "
        f"{m['aoe_deg_raw_imu']} | | |\n"
    )
    return f"""# EuRoC test sequences corrected through `gyrodenoise-correct` (no ground truth given to it)

Command: `{r["command"]}` ({r["date"]})
Model: `{r["model"]}` {json.dumps(r["model_meta"])}

{head}{body}
AOE of the CLI's TUM orientation file (identity start, aligned on the ground truth at the first
instant), for the batch model and the streaming corrector; "evaluation path": predict_gyro +
integrate_gyro on the same samples, as `gyrodenoise.evaluate` computes Table 1.
"""


if __name__ == "__main__":
    main()
