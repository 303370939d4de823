"""Round 6 of the EuRoC recipe selection: subtract the gyro bias measured while the vehicle is at rest.

    python benchmarks/cv_rest_bias.py

The rule is written in benchmarks/queues/cv_round6.txt (committed before any figure of the candidates). For each
fold k: the 3-member ensemble of ref (seeds 100+k, 200+k, 300+k, rounds 2-3) and the calibrated model fitted by the
same runs on the same training flights; on the held-out flight, whole, each model's corrected gyro minus its causal
rest-bias estimate (`RestDetector` below, rest detected on the raw IMU). AOE 3D per fold; figure = mean over
folds; the better of the two candidates replaces the plain ensemble only if the paired-by-fold difference has a
95% t-interval below 0. Writes --out .md and .json. CPU only; ~15 s.

Why it could help: at rest the true angular rate is zero, so whatever a corrected gyro reads there is the
correction's own error, mostly the flight's bias (reports/accuracy.md, "What is left of the error once a flight's
gyro bias is known"). Every output sample of the rest-bias estimate uses past and present samples only.
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from cv_ensemble_figure import ROUND3_ROOTS, aoe_deg, find_runs, fold_ensemble_and_calibrated, round_decision
from cv_slow_part import causal_mean
from scipy.spatial.transform import Rotation

from gyrodenoise.atomic import write_json, write_text
from gyrodenoise.tables import markdown_table

CANDIDATES = ("ensemble+rest", "calibrated+rest")


@dataclass(frozen=True)
class RestDetector:
    """Rest = the trailing `window_s` means of gyro and accelerometer moved less than the tolerances over
    the last `window_s` (so 2 windows of data look still). Defaults: benchmarks/queues/cv_round6.txt."""

    window_s: float = 1.0
    gyro_tol: float = 0.01  # rad/s, change of the 1-s mean gyro
    acc_tol: float = 0.1  # m/s^2, change of the 1-s mean accelerometer

    def window(self, rate_hz: float) -> int:
        if not rate_hz > 0:
            raise ValueError(f"rest detection needs a positive IMU rate, got {rate_hz} Hz")
        return max(1, round(self.window_s * rate_hz))

    def flags(self, gyro: np.ndarray, acc: np.ndarray, rate_hz: float) -> np.ndarray:
        """(N,) bool: sample n ends 2 windows of still IMU data. False while fewer than 2 windows exist."""
        w = self.window(rate_hz)
        gyro, acc = _check(gyro, "gyro"), _check(acc, "acc")
        if len(gyro) != len(acc):
            raise ValueError(f"rest detection: gyro has {len(gyro)} samples, acc {len(acc)}")
        flags = np.zeros(len(gyro), dtype=bool)
        if len(gyro) < 2 * w:
            return flags
        mg, ma = causal_mean(gyro, w), causal_mean(acc, w)
        dg = np.linalg.norm(mg[w:] - mg[:-w], axis=1)
        da = np.linalg.norm(ma[w:] - ma[:-w], axis=1)
        flags[w:] = (dg < self.gyro_tol) & (da < self.acc_tol)
        flags[: 2 * w - 1] = False  # the first full pair of windows ends at sample 2w - 1
        return flags


def rest_periods(flags: np.ndarray) -> list[tuple[int, int]]:
    """[(first, last)] inclusive sample indices of each run of consecutive True flags."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], flags.astype(np.int8), [0]])))
    return [(int(a), int(b) - 1) for a, b in zip(edges[::2], edges[1::2], strict=True)]


def rest_bias(corrected: np.ndarray, flags: np.ndarray, window: int) -> np.ndarray:
    """(N, 3) causal bias estimate: during a run of flags [s, e], the mean of `corrected` over
    [s - 2 window + 1, n]; held after e until the next run; zero before the first run."""
    corrected = _check(corrected, "corrected gyro")
    if len(flags) != len(corrected):
        raise ValueError(f"rest bias: {len(flags)} flags for {len(corrected)} gyro samples")
    bias = np.zeros_like(corrected, dtype=np.float64)
    csum = np.concatenate([np.zeros((1, 3)), np.cumsum(corrected, axis=0, dtype=np.float64)])
    periods = rest_periods(flags)
    for i, (s, e) in enumerate(periods):
        a = max(0, s - 2 * window + 1)
        n = np.arange(s, e + 1)
        bias[s : e + 1] = (csum[n + 1] - csum[a]) / (n - a + 1)[:, None]
        stop = periods[i + 1][0] if i + 1 < len(periods) else len(corrected)
        bias[e + 1 : stop] = bias[e]
    return bias


def remove_rest_bias(
    corrected: np.ndarray, imu: np.ndarray, rate_hz: float, detector: RestDetector | None = None
) -> np.ndarray:
    """`corrected` (N, 3) minus its causal rest-bias estimate; rest is detected on the raw `imu` (N, 6)."""
    detector = detector or RestDetector()
    imu = np.asarray(imu)
    if imu.ndim != 2 or imu.shape[1] != 6:
        raise ValueError(f"rest bias: imu must be (N, 6) gyro then accelerometer, got shape {imu.shape}")
    flags = detector.flags(imu[:, :3], imu[:, 3:], rate_hz)
    return corrected - rest_bias(corrected, flags, detector.window(rate_hz))


def _check(x: np.ndarray, what: str) -> np.ndarray:
    x = np.asarray(x)
    if x.ndim != 2 or x.shape[1] != 3:
        raise ValueError(f"rest bias: {what} must be (N, 3), got shape {x.shape}")
    if not np.isfinite(x).all():
        row = int(np.argmax(~np.isfinite(x).all(axis=1)))
        raise ValueError(f"rest bias: {what} has non-finite values (first at row {row})")
    return x


def strict_rest_blocks(seq) -> np.ndarray:
    """Sample indices of the whole 1-s blocks that are still by strict IMU-only tests (the 1-s mean gyro moved
    < 0.1 deg/s and the mean accelerometer < 0.02 m/s^2 since the previous block, per-sample gyro sd < 1 deg/s).
    Diagnostic only, chosen after round 6's figure: it drops the settling and hovering round 6's detector let in."""
    w = round(seq.rate_hz)
    keep = []
    for i in range(1, len(seq) // w):
        now, before = slice(i * w, (i + 1) * w), slice((i - 1) * w, i * w)
        dg = np.linalg.norm(seq.gyro[now].mean(0) - seq.gyro[before].mean(0))
        da = np.linalg.norm(seq.acc[now].mean(0) - seq.acc[before].mean(0))
        if dg < np.radians(0.1) and da < 0.02 and seq.gyro[now].std(0).max() < np.radians(1.0):
            keep.append(np.arange(now.start, now.stop))
    return np.concatenate(keep) if keep else np.zeros(0, dtype=int)


def offsets_at_rest(seq, models: dict[str, np.ndarray], hindsight: dict) -> list[dict]:
    """Per model: the constant offset (deg/s) that zeroes its corrected gyro over the strict rest blocks, beside
    the AOE-minimising offset of benchmarks/results/bias_hindsight.json (same sign convention: added)."""
    idx = strict_rest_blocks(seq)
    gt_rate = np.full(3, np.nan)
    if len(idx):
        w = round(seq.rate_hz)
        starts = idx[::w]  # strict blocks are whole w-sample blocks
        turn = Rotation.from_matrix(seq.rot[starts]).inv() * Rotation.from_matrix(seq.rot[starts + w - 1])
        gt_rate = np.degrees(turn.as_rotvec()).mean(0) * seq.rate_hz / (w - 1)
    rows = []
    for name, gyro in models.items():
        rest = -np.degrees(gyro[idx].mean(0)) if len(idx) else np.full(3, np.nan)
        rows.append(
            {
                "flight": seq.name,
                "model": name,
                "rest_s": len(idx) / seq.rate_hz,
                "rest_offset_deg_s": rest.tolist(),
                "hindsight_offset_deg_s": hindsight[(seq.name, name)],
                "gt_turn_rate_at_rest_deg_s": gt_rate.tolist(),
            }
        )
    return rows


def load_hindsight(path: Path = Path("benchmarks/results/bias_hindsight.json")) -> dict:
    names = {"ref ensemble": "ensemble", "calibrated": "calibrated"}
    rows = json.loads(path.read_text())["rows"]
    return {
        (r["flight"], names[r["model"]]): r["offset_deg_s"]
        for r in rows
        if r["set"] == "cross-validation" and r["model"] in names
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", type=Path, default=Path("benchmarks/results/cv_rest_bias"))
    args = ap.parse_args()
    start = time.time()
    runs = find_runs(ROUND3_ROOTS)
    detector = RestDetector()
    folds, offsets = [], []
    hindsight = load_hindsight()
    for k in range(6):
        seq, ens, cal = fold_ensemble_and_calibrated(k, runs)
        flags = detector.flags(seq.gyro, seq.acc, seq.rate_hz)
        periods = [(round(seq.t[a], 1), round(seq.t[b], 1)) for a, b in rest_periods(flags)]
        row = {
            "fold": k,
            "held_out": seq.name,
            "rest_flagged_s": float(flags.sum() / seq.rate_hz),
            "rest_periods_s": periods,
            "ensemble": aoe_deg(seq, ens),
            "calibrated": aoe_deg(seq, cal),
            "ensemble+rest": aoe_deg(seq, remove_rest_bias(ens, seq.imu, seq.rate_hz, detector)),
            "calibrated+rest": aoe_deg(seq, remove_rest_bias(cal, seq.imu, seq.rate_hz, detector)),
        }
        folds.append(row)
        offsets += offsets_at_rest(seq, {"ensemble": ens, "calibrated": cal}, hindsight)
        print(k, seq.name, periods, {key: round(v, 2) for key, v in row.items() if isinstance(v, float)}, flush=True)
    result = {
        "command": "python benchmarks/cv_rest_bias.py",
        "rule": "benchmarks/queues/cv_round6.txt",
        "machine": f"{platform.node()} ({platform.machine()}, CPU)",
        "detector": vars(detector),
        "wall_s": time.time() - start,
        "folds": folds,
        **round_decision(folds, list(CANDIDATES)),
        "offsets_at_rest": offsets,
    }
    write_json(args.out.with_suffix(".json"), result)
    write_text(args.out.with_suffix(".md"), report(result))
    print(result["decision"], {k: round(v, 2) for k, v in result["figure"].items()})


def report(result: dict) -> str:
    keys = ["ensemble", "calibrated", *CANDIDATES]
    rows = [
        [
            str(f["fold"]),
            f["held_out"],
            ", ".join(f"{a:g}-{b:g}" for a, b in f["rest_periods_s"]) or "none",
            *[f"{f[k]:.2f}" for k in keys],
        ]
        for f in result["folds"]
    ]
    rows.append(["", "**mean**", "", *[f"**{result['figure'][k]:.2f}**" for k in keys]])
    lo, hi = result["diff_t_ci"]
    return "\n".join(
        [
            "# Round 6 of the EuRoC selection: the gyro bias measured at rest",
            "",
            f"`{result['command']}` on {result['machine']}, {result['wall_s']:.0f} s. Rule: `{result['rule']}` "
            "(written before any figure of the candidates). Held-out-flight AOE 3D (deg), each flight whole. "
            "+rest: the model's corrected gyro minus its causal rest-bias estimate (`RestDetector` below, "
            f"detector {result['detector']}); rest periods are the runs of rest flags (s from the flight's start; "
            "a flag at t means the 2 s before t look still).",
            "",
            markdown_table(["fold", "held-out flight", "rest periods (s)", *keys], rows),
            "",
            f"- chosen (lower figure of the two candidates, on these folds): {result['chosen']}; {result['chosen']} − "
            f"ensemble per fold {result['diff_mean']:+.2f} deg, "
            f"95% t-interval [{lo:+.2f}, {hi:+.2f}] ({result['verdict']})",
            "",
            f"**Decision by the rule: {result['decision']}.**",
            "",
            "## Why: the offset a rest measures against the offset the flight needed (diagnostic, no rule)",
            "",
            "Chosen after the figure above and used by no rule. Strict rest: whole 1-s blocks whose 1-s mean gyro "
            "moved < 0.1 deg/s and mean accelerometer < 0.02 m/s^2 since the previous block, per-sample gyro sd "
            "< 1 deg/s. 'at rest': the offset (deg/s, body x y z, added) that zeroes the model's corrected gyro "
            "over those blocks; 'hindsight': the AOE-minimising constant offset of the whole flight "
            "(benchmarks/results/bias_hindsight.json); the ground truth's turn rate: its mean rotation rate over the "
            "same blocks, where the vehicle is still. Body x is about vertical in EuRoC.",
            "",
            markdown_table(
                [
                    "held-out flight",
                    "model",
                    "strict rest (s)",
                    "offset at rest",
                    "hindsight offset",
                    "difference",
                    "ground truth's turn rate at rest",
                ],
                [
                    [
                        o["flight"],
                        o["model"],
                        f"{o['rest_s']:.0f}",
                        _vec(o["rest_offset_deg_s"]),
                        _vec(o["hindsight_offset_deg_s"]),
                        _vec(np.subtract(o["rest_offset_deg_s"], o["hindsight_offset_deg_s"])),
                        _vec(o["gt_turn_rate_at_rest_deg_s"]),
                    ]
                    for o in result["offsets_at_rest"]
                ],
            ),
            "",
        ]
    )


def _vec(v) -> str:
    return " ".join(f"{x:+.3f}" for x in v)


if __name__ == "__main__":
    main()
