"""Time the authors' public implementation (github.com/mbrossar/denoise-imu-gyro) on this project's EuRoC data,
for issue 9's side-by-side GPU figure. Their code is not part of this repository: point --authors at a checkout.

    python benchmarks/authors_code_timing.py --authors DIR [--data DATA/euroc] [--epochs 1800] [--json OUT.json]

Runs their EuRoC recipe unchanged (the parameters of their main_EUROC.py: GyroNet, Adam lr 0.01 wd 0.1, cosine
warm restarts T_0 600 T_mult 2, 16000-sample crops, validation every 600 epochs), with only the paths (data, their
preloaded-data and result folders, in a temporary folder) and, with --epochs, the schedule length set here. Their
preprocessing (reading every sequence folder of --data into their pickles) runs first and is timed apart; then
their `train` (datasets, the 1800-epoch loop with its validations, their final test loss) is timed as one wall
time, and the loop's own per-validation-interval times are read from what it prints. Needs a CUDA device (their
code assumes one) and the package `termcolor`.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import re
import sys
import tempfile
import time
from pathlib import Path


class _Tee(io.TextIOBase):
    def __init__(self, *streams) -> None:
        self.streams = streams

    def write(self, s: str) -> int:
        for st in self.streams:
            st.write(s)
        return len(s)

    def flush(self) -> None:
        for st in self.streams:
            st.flush()


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--authors", type=Path, required=True, help="checkout of mbrossar/denoise-imu-gyro")
    ap.add_argument("--data", type=Path, default=Path("../shared/data/euroc"), help="EuRoC root (ASL folders)")
    ap.add_argument("--epochs", type=int, default=1800)
    ap.add_argument("--seed", type=int, default=0, help="torch.manual_seed before training (their code sets none)")
    ap.add_argument("--json", type=Path, default=None, help="write the timings here")
    args = ap.parse_args()
    if not (args.authors / "src" / "learning.py").is_file():
        raise SystemExit(f"--authors {args.authors}: no src/learning.py there; give a checkout of denoise-imu-gyro")
    if not args.data.is_dir():
        raise SystemExit(f"--data {args.data}: no such folder; give the EuRoC root that holds MH_01_easy/mav0")
    import numpy as np
    import torch

    if not torch.cuda.is_available():
        raise SystemExit("the authors' code needs a CUDA device (torch.cuda.is_available() is False)")
    sys.path.insert(0, str(args.authors.resolve()))
    import src.dataset as ds  # their modules
    import src.learning as lr
    import src.losses as sl
    import src.networks as sn

    work = Path(tempfile.mkdtemp(prefix="authors_code_"))
    (work / "predata").mkdir()
    (work / "results").mkdir()
    train_seqs = ["MH_01_easy", "MH_03_medium", "MH_05_difficult", "V1_02_medium", "V2_01_easy", "V2_03_difficult"]
    test_seqs = ["MH_02_easy", "MH_04_difficult", "V2_02_medium", "V1_03_difficult", "V1_01_easy"]
    net_params = {
        "in_dim": 6,
        "out_dim": 3,
        "c0": 16,
        "dropout": 0.1,
        "ks": [7, 7, 7, 7],
        "ds": [4, 4, 4],
        "momentum": 0.1,
        "gyro_std": [1 * np.pi / 180, 2 * np.pi / 180, 5 * np.pi / 180],
    }
    dataset_params = {
        "data_dir": str(args.data.resolve()),
        "predata_dir": str(work / "predata"),
        "train_seqs": train_seqs,
        "val_seqs": train_seqs,
        "test_seqs": test_seqs,
        "N": 32 * 500,
        "min_train_freq": 16,
        "max_train_freq": 32,
    }
    train_params = {
        "optimizer_class": torch.optim.Adam,
        "optimizer": {"lr": 0.01, "weight_decay": 1e-1, "amsgrad": False},
        "loss_class": sl.GyroLoss,
        "loss": {"min_N": 4, "max_N": 5, "w": 1e6, "target": "rotation matrix", "huber": 0.005, "dt": 0.005},
        "scheduler_class": torch.optim.lr_scheduler.CosineAnnealingWarmRestarts,
        "scheduler": {"T_0": 600, "T_mult": 2, "eta_min": 1e-3},
        "dataloader": {"batch_size": 10, "pin_memory": False, "num_workers": 0, "shuffle": False},
        "freq_val": 600,
        "n_epochs": args.epochs,
        "res_dir": str(work / "results"),
        "tb_dir": str(work / "runs"),
    }
    start = time.perf_counter()
    ds.EUROCDataset(**dataset_params, mode="train")  # their read_data: every sequence folder -> pickles
    prep_s = time.perf_counter() - start
    torch.manual_seed(args.seed)
    proc = lr.GyroLearningBasedProcessing(
        train_params["res_dir"], train_params["tb_dir"], sn.GyroNet, net_params, None, train_params["loss"]["dt"]
    )
    log = io.StringIO()
    torch.cuda.synchronize()
    start = time.perf_counter()
    with contextlib.redirect_stdout(_Tee(sys.stdout, log)):
        proc.train(ds.EUROCDataset, dataset_params, train_params)
    torch.cuda.synchronize()
    train_s = time.perf_counter() - start
    intervals = [float(x) for x in re.findall(r"Amount of time spent for epochs \d+-\d+: ([0-9.]+)s", log.getvalue())]
    out = {
        "what": "authors' code (mbrossar/denoise-imu-gyro), EuRoC recipe of main_EUROC.py",
        "epochs": args.epochs,
        "seed": args.seed,
        "preprocessing_s": round(prep_s, 2),
        "train_call_wall_s": round(train_s, 2),
        "loop_intervals_s": intervals,
        "loop_s": round(sum(intervals), 2),
        "device": torch.cuda.get_device_name(0),
        "torch": torch.__version__,
    }
    print("AUTHORS_TIMING " + json.dumps(out))
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        tmp = args.json.with_suffix(".tmp")
        tmp.write_text(json.dumps(out, indent=2) + "\n")
        tmp.replace(args.json)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
