"""Test AOE of EuRoC ensembles built from trained member models (reports/accuracy.md).

    python benchmarks/euroc_ensembles.py MEMBERS_DIR --out benchmarks/results/euroc_ensembles.json

MEMBERS_DIR holds the members' model.pt files named as their runs in
benchmarks/queues/ensemble_members.txt (ref_s0.pt ... ref_f5.pt, whole_s0.pt ...). For each member
and each ensemble below, the corrected gyro of every EuRoC test sequence (V1_01 against the
recomputed ground truth) is integrated open loop and scored with the project's AOE. An ensemble's
corrected gyro is the mean of its members' (what gyrodenoise's ensemble model computes). CPU only.
"""

from __future__ import annotations

import argparse
import math
import platform
import time
from pathlib import Path

import hydra
import numpy as np

from gyrodenoise.atomic import write_json
from gyrodenoise.config import compose_config
from gyrodenoise.metrics import aoe
from gyrodenoise.models.denoiser import predict_gyro
from gyrodenoise.pretrained import load_model
from gyrodenoise.so3 import integrate_gyro

ENSEMBLES = {  # name -> member file stems
    "ref seeds 0-7 (K=8)": [f"ref_s{s}" for s in range(8)],
    "ref seeds 0-3 (K=4)": [f"ref_s{s}" for s in range(4)],
    "ref seeds 4-7 (K=4)": [f"ref_s{s}" for s in range(4, 8)],
    "ref folds 0-5 (K=6)": [f"ref_f{f}" for f in range(6)],
    "whole seeds 0-7 (K=8)": [f"whole_s{s}" for s in range(8)],
    "whole seeds 0-3 (K=4)": [f"whole_s{s}" for s in range(4)],
    "whole seeds 4-7 (K=4)": [f"whole_s{s}" for s in range(4, 8)],
}


def test_sequences() -> list:
    cfg = compose_config("train", ["dataset=euroc"])
    dm = hydra.utils.instantiate(cfg.dataset)
    dm.setup("test")
    return dm.test_part


def score(seqs: list, gyros: list[np.ndarray]) -> dict[str, float]:
    out = {}
    for seq, g in zip(seqs, gyros, strict=True):
        R = integrate_gyro(seq.rot[0], g, seq.dt)
        out[seq.name] = math.degrees(aoe(seq.rot, R, seq.gt_mask)[0])
    out["average"] = float(np.mean(list(out.values())))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("members", type=Path, help="folder of member model files")
    ap.add_argument("--out", type=Path, default=Path("benchmarks/results/euroc_ensembles.json"))
    args = ap.parse_args()
    start = time.time()
    seqs = test_sequences()
    gyro = {}  # member -> list of (N, 3) corrected gyro per test sequence
    for path in sorted(args.members.glob("*.pt")):
        model, _ = load_model(path)
        gyro[path.stem] = [predict_gyro(model, s.imu).numpy() for s in seqs]
    members = {m: score(seqs, g) for m, g in gyro.items()}
    ensembles = {}
    for name, stems in ENSEMBLES.items():
        if all(s in gyro for s in stems):
            mean = [np.mean([gyro[s][k] for s in stems], axis=0) for k in range(len(seqs))]
            ensembles[name] = {"members": stems, "aoe_deg": score(seqs, mean)}
    result = {
        "command": f"python benchmarks/euroc_ensembles.py {args.members} --out {args.out}",
        "machine": f"{platform.node()} ({platform.machine()}, CPU)",
        "wall_s": time.time() - start,
        "members": members,
        "ensembles": ensembles,
    }
    write_json(args.out, result)
    for name, e in ensembles.items():
        print(f"{name:28s} {e['aoe_deg']['average']:.2f}")


if __name__ == "__main__":
    main()
