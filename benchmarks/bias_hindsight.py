"""How much of a flight's attitude error is one constant gyro bias? (reports/accuracy.md, "What is left")

    python benchmarks/bias_hindsight.py

For each model and flight: the AOE 3D of the open-loop integration as it is, then the constant gyro offset b
(deg/s, body axes) that minimises that AOE in hindsight (Nelder-Mead from 0, ground truth used: a bound, not a
method), the AOE with it, and the AOE with only its part along the world vertical (the yaw part, which the
accelerometer cannot observe) or only its horizontal part (roll/pitch, which gravity makes observable over
time). Two sets of flights:
- cross-validation: each EuRoC training flight held out, scored with its fold's 3-member ensemble of the `ref`
  recipe (seeds 100+k, 200+k, 300+k: round 3 of the selection) and with the calibrated model fitted by the
  same runs on the same training data (`calibrated.pt` of the seed-100+k run);
- test: the five EuRoC test flights (V1_01 against the recomputed ground truth), shipped `euroc` and
  `euroc-calibrated`.
Nothing here selects a model. Writes --out .md and .json. CPU only; ~5 min.
"""

from __future__ import annotations

import argparse
import platform
import time
from pathlib import Path

import hydra
import numpy as np
from cv_ensemble_figure import ROUND3_ROOTS, aoe_deg, find_runs, fold_ensemble_and_calibrated
from error_by_window import world_up_in_body
from scipy.optimize import minimize

from gyrodenoise.atomic import write_json, write_text
from gyrodenoise.config import compose_config
from gyrodenoise.models.denoiser import predict_gyro
from gyrodenoise.pretrained import load_model
from gyrodenoise.tables import markdown_table


def aoe_with_offset(seq, gyro: np.ndarray, offset_deg_s: np.ndarray) -> float:
    """AOE 3D (deg) of the integration of `gyro` + a constant offset (deg/s, body axes)."""
    return aoe_deg(seq, gyro + np.radians(offset_deg_s)[None, :])


def hindsight(seq, gyro: np.ndarray) -> dict:
    """The AOE-minimising constant offset and what its vertical and horizontal parts each recover."""
    res = minimize(
        lambda b: aoe_with_offset(seq, gyro, b),
        np.zeros(3),
        method="Nelder-Mead",
        options={"xatol": 1e-4, "fatol": 1e-3, "initial_simplex": np.vstack([np.zeros(3), 0.05 * np.eye(3)])},
    )
    up = np.median(world_up_in_body(seq), axis=0)
    up /= np.linalg.norm(up)
    vertical = float(res.x @ up) * up
    return {
        "aoe_deg": aoe_with_offset(seq, gyro, np.zeros(3)),
        "offset_deg_s": res.x.tolist(),
        "offset_vertical_deg_s": float(res.x @ up),
        "offset_horizontal_deg_s": float(np.linalg.norm(res.x - vertical)),
        "aoe_offset_deg": float(res.fun),
        "aoe_vertical_only_deg": aoe_with_offset(seq, gyro, vertical),
        "aoe_horizontal_only_deg": aoe_with_offset(seq, gyro, res.x - vertical),
    }


def cv_cases() -> list[tuple[str, object, dict]]:
    """(set, flight, {model label: corrected gyro}) for every held-out flight of the EuRoC folds."""
    runs = find_runs(ROUND3_ROOTS)
    cases = []
    for k in range(6):
        seq, ens, cal = fold_ensemble_and_calibrated(k, runs)
        cases.append(("cross-validation", seq, {"ref ensemble": ens, "calibrated": cal}))
    return cases


def test_cases() -> list[tuple[str, object, dict]]:
    dm = hydra.utils.instantiate(compose_config("train", ["dataset=euroc"]).dataset)
    models = {name: load_model(name)[0] for name in ("euroc", "euroc-calibrated")}
    cases = []
    for name in dm.test_names:
        seq = dm.load(name)
        cases.append(("test", seq, {label: predict_gyro(m, seq.imu).numpy() for label, m in models.items()}))
    return cases


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", type=Path, default=Path("benchmarks/results/bias_hindsight"))
    args = ap.parse_args()
    start = time.time()
    rows = []
    for set_name, seq, gyros in cv_cases() + test_cases():
        for label, gyro in gyros.items():
            rows.append({"set": set_name, "flight": seq.name, "model": label, **hindsight(seq, gyro)})
            r = rows[-1]
            print(f"{set_name} {seq.name} {label}: {r['aoe_deg']:.2f} -> {r['aoe_offset_deg']:.2f} deg", flush=True)
    result = {
        "command": "python benchmarks/bias_hindsight.py",
        "machine": f"{platform.node()} ({platform.machine()}, CPU)",
        "wall_s": time.time() - start,
        "rows": rows,
        "means": means(rows),
    }
    write_json(args.out.with_suffix(".json"), result)
    write_text(args.out.with_suffix(".md"), report(result))


def means(rows: list[dict]) -> list[dict]:
    out = []
    for key in dict.fromkeys((r["set"], r["model"]) for r in rows):
        sel = [r for r in rows if (r["set"], r["model"]) == key]
        out.append(
            {
                "set": key[0],
                "model": key[1],
                "flights": len(sel),
                **{
                    f: float(np.mean([r[f] for r in sel]))
                    for f in ("aoe_deg", "aoe_offset_deg", "aoe_vertical_only_deg", "aoe_horizontal_only_deg")
                },
            }
        )
    return out


def report(result: dict) -> str:
    header = [
        "set",
        "flight",
        "model",
        "AOE (deg)",
        "offset b (deg/s, x y z)",
        "b vertical / horizontal (deg/s)",
        "AOE with b",
        "with vertical part only",
        "with horizontal part only",
    ]
    rows = [
        [
            r["set"],
            r["flight"],
            r["model"],
            f"{r['aoe_deg']:.2f}",
            " ".join(f"{v:+.3f}" for v in r["offset_deg_s"]),
            f"{r['offset_vertical_deg_s']:+.3f} / {r['offset_horizontal_deg_s']:.3f}",
            f"**{r['aoe_offset_deg']:.2f}**",
            f"{r['aoe_vertical_only_deg']:.2f}",
            f"{r['aoe_horizontal_only_deg']:.2f}",
        ]
        for r in result["rows"]
    ]
    mean_rows = [
        [
            m["set"],
            f"mean of {m['flights']}",
            m["model"],
            f"{m['aoe_deg']:.2f}",
            "",
            "",
            f"**{m['aoe_offset_deg']:.2f}**",
            f"{m['aoe_vertical_only_deg']:.2f}",
            f"{m['aoe_horizontal_only_deg']:.2f}",
        ]
        for m in result["means"]
    ]
    return "\n".join(
        [
            "# How much of the attitude error is one constant gyro bias per flight?",
            "",
            f"`{result['command']}` on {result['machine']}, {result['wall_s']:.0f} s. AOE 3D (deg) of the open-loop "
            "integration, each flight whole, as it is and with the constant gyro offset b that minimises it in "
            "hindsight (fitted on the flight's ground truth: a bound, not a method). Vertical: b's component along "
            "the flight's median world vertical in the body frame (yaw; the accelerometer cannot observe it); "
            "horizontal: the rest (roll/pitch; observable from gravity over time). Cross-validation: fold "
            "ensembles of `ref` (seeds 100/200/300 + k) and the same runs' calibrated model, on the held-out "
            "flight; test: shipped `euroc` and `euroc-calibrated`, V1_01 against the recomputed ground truth.",
            "",
            markdown_table(header, rows + mean_rows),
            "",
        ]
    )


if __name__ == "__main__":
    main()
