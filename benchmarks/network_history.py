"""How much the IMU before a scored part changes the network's score: `evaluate`'s stream against the whole recording.

    python benchmarks/network_history.py --out benchmarks/results/network_history

`evaluate` runs the network on a scored part alone (a test sequence cropped to its ground truth, `split=val`'s
`NAME[50s:]`, V1_01 against its original ground truth): the network gets no IMU from before the part's first sample.
`gyrodenoise-correct` on the whole recording gives it that history. For each part this scores both over the same
samples, with the same alignment (the part's first ground-truth sample) and AOE (`gyrodenoise.metrics.aoe`):

- "evaluate": `gyrodenoise.evaluate`'s own path (`gyro_method`, `estimate`) on the part, as Table 1 is computed;
- "whole recording": `gyrodenoise.correct.correct_arrays` (the checks and batch model of `gyrodenoise-correct`) on
  every sample of the recording's imu0/data.csv, its corrected gyro on the part's samples integrated by `estimate`.

Parts: the EuRoC test flights (the configured ground truth, and V1_01 against its original one) with `euroc`, and
TUM-VI's validation parts (rooms 1, 3, 5 from 50 s on) with `tumvi-denoiser`. The calibrated model of each dataset
(`euroc-calibrated`, `tumvi-calibrated`) corrects each sample alone and is scored both ways too, as a check that
only the network's history differs. Writes OUT.md and OUT.json. CPU only (about a minute of inference on 2 cores).
"""

from __future__ import annotations

import argparse
import time
import warnings
from pathlib import Path

import hydra
import numpy as np

from gyrodenoise.atomic import write_json, write_text
from gyrodenoise.config import compose_config
from gyrodenoise.correct import correct_arrays
from gyrodenoise.data.cache import load_sequence
from gyrodenoise.data.readers import read_imu
from gyrodenoise.data.sequence import Sequence
from gyrodenoise.evaluate import estimate, gyro_method
from gyrodenoise.metrics import aoe
from gyrodenoise.pretrained import load_model
from gyrodenoise.provenance import machine_description
from gyrodenoise.tables import markdown_table

SETUPS = {  # dataset -> (split, network, calibrated model)
    "euroc": ("test", "euroc", "euroc-calibrated"),
    "tumvi": ("val", "tumvi-denoiser", "tumvi-calibrated"),
}


def parts(dataset: str, split: str) -> list[tuple[str, Sequence]]:
    """(row label, scored part) as `evaluate dataset=DATASET split=SPLIT` builds them."""
    dm = hydra.utils.instantiate(compose_config("train", [f"dataset={dataset}"]).dataset)
    dm.inconsistent_truth = "warn"
    dm.setup("test" if split == "test" else "fit")
    out = []
    for seq in dm.test_part if split == "test" else dm.val_part:
        gt_file = dm.gt_files.get(seq.name)
        out.append((f"{seq.name} ({Path(gt_file).stem})" if gt_file else seq.name, seq))
        for variant, variant_file in dm.eval_gt_variants.get(seq.name, {}).items():
            extra = load_sequence(dm.root, seq.name, variant_file, dm.max_gap_factor, dm.cache_dir)
            out.append((f"{seq.name} ({variant})", extra))
    return out


def whole_recording(seq: Sequence, model: str) -> tuple[np.ndarray, np.ndarray, float]:
    """The corrected gyro of `model` over the part's samples when the whole recording is corrected, the part's
    indices in the recording, and the seconds of IMU before the part."""
    imu = read_imu(seq.meta["imu_file"])
    idx = np.searchsorted(imu.t_ns, seq.t_ns)
    if idx.max() >= len(imu.t_ns) or not np.array_equal(imu.t_ns[idx], seq.t_ns):
        raise RuntimeError(f"{seq.name}: the part's stamps are not samples of {seq.meta['imu_file']}")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the data checks' notes (e.g. TUM-VI's rate) change nothing scored here
        res = correct_arrays(imu.t_ns, imu.gyro, imu.acc, model, time_unit="ns")
    if len(res.gyro) != len(imu.t_ns):
        raise RuntimeError(f"{seq.name}: the correction resampled or dropped samples; the part cannot be matched")
    return res.gyro[idx], idx, float((seq.t_ns[0] - imu.t_ns[0]) * 1e-9)


def score(seq: Sequence, gyro: np.ndarray) -> float:
    return float(np.degrees(aoe(seq.rot, estimate(seq, gyro), seq.gt_mask)[0]))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--datasets", nargs="+", default=list(SETUPS), choices=list(SETUPS))
    ap.add_argument("--out", type=Path, default=Path("benchmarks/results/network_history"))
    args = ap.parse_args()
    start = time.time()
    rows = []
    for dataset in args.datasets:
        split, network, calibrated = SETUPS[dataset]
        models = {name: load_model(name, warn=False)[0] for name in (network, calibrated)}
        for label, seq in parts(dataset, split):
            row = {"dataset": dataset, "split": split, "part": label, "samples": len(seq)}
            for role, name in (("network", network), ("calibrated", calibrated)):
                own = score(seq, gyro_method(models[name])(seq))
                gyro, _, before = whole_recording(seq, name)
                hist = score(seq, gyro)
                row |= {f"{role}": name, f"{role}_evaluate_deg": own, f"{role}_whole_deg": hist}
                row |= {f"{role}_diff_deg": hist - own, "imu_before_part_s": before}
            rows.append(row)
            print(row, flush=True)
    table = [
        [
            r["dataset"],
            r["part"],
            f"{r['imu_before_part_s']:.2f}",
            r["network"],
            f"{r['network_evaluate_deg']:.4f}",
            f"{r['network_whole_deg']:.4f}",
            f"{r['network_diff_deg']:+.4f}",
            f"{r['calibrated_diff_deg']:+.1e}",
        ]
        for r in rows
    ]
    summary = []
    for dataset in args.datasets:
        d = [abs(r["network_diff_deg"]) for r in rows if r["dataset"] == dataset and "original" not in r["part"]]
        s = [r["imu_before_part_s"] for r in rows if r["dataset"] == dataset and "original" not in r["part"]]
        summary.append([dataset, SETUPS[dataset][1], f"{min(d):.4f}-{max(d):.4f}", f"{min(s):.2f}-{max(s):.2f}"])
    md = [
        "# The network's IMU history: a part scored alone (`evaluate`) and within its whole recording",
        "",
        f"`python benchmarks/network_history.py --out {args.out}` ({machine_description()}, "
        f"{time.time() - start:.0f} s).",
        "",
        "AOE 3D (deg) over the part's samples, aligned on the ground truth at its first sample. *evaluate*: the "
        "network run on the part alone (`gyrodenoise.evaluate`'s path, as its tables); *whole recording*: "
        "`gyrodenoise.correct.correct_arrays` (as `gyrodenoise-correct`) on every sample of the recording's "
        "imu0/data.csv, scored on the part's samples. *IMU before*: seconds of the recording before the part's first "
        "sample. The calibrated model corrects each sample alone: its difference shows that nothing else differs.",
        "",
        markdown_table(["dataset", "model", "abs difference, averaged parts", "IMU before (s)"], summary),
        "",
        markdown_table(
            [
                "dataset",
                "part",
                "IMU before (s)",
                "network",
                "evaluate",
                "whole recording",
                "difference",
                "calibrated: difference",
            ],
            table,
        ),
        "",
    ]
    write_text(args.out.with_suffix(".md"), "\n".join(md))
    command = f"python benchmarks/network_history.py --out {args.out}"
    info = {"command": command, "machine": machine_description()}
    write_json(args.out.with_suffix(".json"), info | {"rows": rows, "wall_s": round(time.time() - start)})
    print("\n".join(md))


if __name__ == "__main__":
    main()
