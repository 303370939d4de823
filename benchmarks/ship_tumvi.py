"""Write the shipped `tumvi` default: the calibrated model fitted on TUM-VI rooms 1, 3 and 5 whole.

    python benchmarks/calibrated_cv.py --datasets tumvi   # the cross-validation that chose it (first)
    python benchmarks/ship_tumvi.py

The fit is `python -m gyrodenoise.fit_calibrated dataset=tumvi test=false dataset.train_duration_s=null`
(deterministic L-BFGS, ~1 s); this script runs it into a temporary folder and writes the model file to
src/gyrodenoise/weights/tumvi.pt with the selection figures of benchmarks/results/calibrated_cv.json and of
the denoiser rounds (benchmarks/results/tumvi_nobn.json, tumvi_round2.json) in its metadata.
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import numpy as np
import torch

from gyrodenoise.config import compose_config
from gyrodenoise.fit_calibrated import fit
from gyrodenoise.pretrained import load_model, save_model, shipped_dir

COMMAND = "python -m gyrodenoise.fit_calibrated dataset=tumvi test=false dataset.train_duration_s=null"
RESULTS = Path("benchmarks/results")


def main() -> int:
    # no options; --help shows what it does instead of running it (it writes committed files)
    argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter).parse_args()
    folds = json.loads((RESULTS / "calibrated_cv.json").read_text())["folds"]["tumvi"]
    cv = {k: float(np.mean([f[k] for f in folds])) for k in ("whole", "first 50 s", "raw IMU")}
    round2 = json.loads((RESULTS / "tumvi_round2.json").read_text())["arms"]
    round1 = json.loads((RESULTS / "tumvi_nobn.json").read_text())["runs"]
    denoisers = {
        "nobn (50 s)": float(np.mean([r["model"] for r in round1["nobn"].values()])),
        **{arm: v["aoe"] for arm, v in round2.items()},
    }
    with tempfile.TemporaryDirectory() as tmp:
        overrides = ["dataset=tumvi", "test=false", "dataset.train_duration_s=null", f"paths.output_dir={tmp}"]
        cfg = compose_config("fit_calibrated", overrides)
        fit(cfg)
        model, meta = load_model(Path(tmp) / "model.pt")
    best = min(denoisers, key=denoisers.get)
    meta = {k: v for k, v in meta.items() if k not in ("model", "path", "name")}
    meta.update(
        command=COMMAND,
        cv_aoe_deg=cv["whole"],
        calibrated_50s_cv_aoe_deg=cv["first 50 s"],
        raw_imu_cv_aoe_deg=cv["raw IMU"],
        default_choice=(
            f"tumvi = the 12-parameter calibrated model fitted on rooms 1, 3, 5 whole: in leave-one-room-out "
            f"cross-validation {cv['whole']:.2f} deg against {cv['first 50 s']:.2f} for the same fit on their first "
            f"50 s and {denoisers[best]:.2f} for the best denoiser ({best}); raw IMU {cv['raw IMU']:.2f} "
            "(reports/accuracy.md)"
        ),
    )
    out = save_model(model, {"name": "calibrated"}, shipped_dir() / "tumvi.pt", meta=meta)
    print(f"wrote {out}: {meta['default_choice']}")
    torch.testing.assert_close(load_model("tumvi")[0].state_dict(), model.state_dict())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
