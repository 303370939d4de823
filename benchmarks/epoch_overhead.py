"""What the training loop costs per epoch around the network's arithmetic (issue 9).

    python benchmarks/epoch_overhead.py [--device cpu|cuda] [--rounds 3] [--label TEXT] [TRAIN OVERRIDES ...]

One epoch of gyrodenoise's training is one optimiser step, so where the step's arithmetic is cheap (a GPU:
~45 ms per epoch on an H100, against ~30 for the authors' code) what the loop does around it sets the wall
time: Lightning's hooks, logging, callbacks, and the host-device synchronisations that stop the CPU from
queueing the next step's kernels while the GPU works. This measures that part with the arithmetic made
negligible: `model.channels=[2,2,2,2] dataset.window=64` keeps every layer, operator, data and loss path of
the EuRoC run with tiny tensors.
- loop: `python -m gyrodenoise.train dataset=euroc` with those settings (validation, test and the
  calibrated baseline off) for 200 and 600 epochs; (wall(600) - wall(200)) / 400 is the cost per epoch,
  start-up cancelling out;
- bare: the same module, data, loss, Adam and scheduler in a plain loop (no Lightning, no logging);
- on CUDA, the host syncs per step of the bare loop (`torch.cuda.set_sync_debug_mode`).
Rounds alternate the two; figures are medians. Appends a row to benchmarks/results/epoch_overhead.{md,json}.
Needs ../shared/data/euroc (or GYRODENOISE_DATA).
"""

from __future__ import annotations

import argparse
import json
import platform
import statistics
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

OUT = Path("benchmarks/results/epoch_overhead")
TINY = ["dataset=euroc", "dataset.window=64", "model.channels=[2,2,2,2]"]
EPOCHS = (200, 600)


def loop_wall(epochs: int, device: str, overrides: list[str]) -> float:
    """train_wall_time_s of a tiny training run of `epochs` epochs."""
    with tempfile.TemporaryDirectory() as tmp:
        cmd = [
            sys.executable,
            "-m",
            "gyrodenoise.train",
            *TINY,
            f"trainer.max_epochs={epochs}",
            f"optim.scheduler.T_0={epochs}",
            "trainer.check_val_every_n_epoch=100000",
            "test=false",
            "calibrated_baseline=false",
            "threads=1",
            f"trainer.accelerator={'gpu' if device == 'cuda' else 'cpu'}",
            f"hydra.run.dir={tmp}",
            *overrides,
        ]
        proc = subprocess.run(cmd, capture_output=True, text=True)
        if proc.returncode != 0:  # the training's own error, not a CalledProcessError that hides it
            raise SystemExit(f"epoch_overhead: the timed training failed:\n{proc.stderr[-2000:]}")
        return json.loads((Path(tmp) / "summary.json").read_text())["train_wall_time_s"]


def bare_epoch_ms(device: str, epochs: int = 300) -> tuple[float, float | None]:
    """Per-epoch ms of a plain loop over the same step, and host syncs per step (CUDA only)."""
    import torch
    from hydra.utils import instantiate

    from gyrodenoise.config import compose_config
    from gyrodenoise.lit import DenoiserModule

    torch.set_num_threads(1)
    cfg = compose_config("train", TINY)
    dm = instantiate(cfg.dataset)
    dm.setup("fit")
    module = DenoiserModule.from_config(cfg)
    module.model.set_normalization(*dm.normalization())
    module.to(device).train()
    opts = module.configure_optimizers()
    opt, sched = opts["optimizer"], opts["lr_scheduler"]["scheduler"]
    loader = dm.train_dataloader()

    def epoch() -> None:
        for batch in loader:
            batch = {k: v.to(device, non_blocking=True) for k, v in batch.items()}
            w_hat = module.model(batch["imu"])
            loss = module.loss_fn(w_hat, batch["dt"], batch["dR"], batch["dR_mask"])
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
        sched.step()

    def sync() -> None:
        if device == "cuda":
            torch.cuda.synchronize()

    for _ in range(20):
        epoch()
    syncs = None
    if device == "cuda":
        torch.cuda.set_sync_debug_mode("warn")
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            epoch()
        torch.cuda.set_sync_debug_mode("default")
        syncs = float(sum("synchroniz" in str(w.message) for w in caught))
    sync()
    start = time.perf_counter()
    for _ in range(epochs):
        epoch()
    sync()
    return (time.perf_counter() - start) / epochs * 1e3, syncs


def machine(device: str) -> str:
    import torch

    gpu = torch.cuda.get_device_name(0) if device == "cuda" else "CPU, 1 thread"
    return f"{platform.node()} ({platform.machine()}, torch {torch.__version__}, {gpu})"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--device", choices=("cpu", "cuda"), default="cpu")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--label", default="", help="what the code measured is (e.g. a commit and what it changes)")
    ap.add_argument("overrides", nargs="*", help="extra train overrides of the loop (e.g. logger=none)")
    args = ap.parse_args()
    import torch

    if args.device == "cuda" and not torch.cuda.is_available():
        ap.error("--device cuda: torch sees no CUDA device on this machine")
    loop, bare, syncs = [], [], []
    for r in range(args.rounds):
        walls = {e: loop_wall(e, args.device, args.overrides) for e in EPOCHS}
        loop.append((walls[EPOCHS[1]] - walls[EPOCHS[0]]) / (EPOCHS[1] - EPOCHS[0]) * 1e3)
        ms, s = bare_epoch_ms(args.device)
        bare.append(ms)
        syncs.append(s)
        print(f"round {r}: loop {loop[-1]:.2f} ms/epoch, bare {bare[-1]:.2f} ms/epoch, syncs {s}", flush=True)
    row = {
        "label": args.label,
        "device": args.device,
        "machine": machine(args.device),
        "command": " ".join(
            ["python benchmarks/epoch_overhead.py --device", args.device, f"--rounds {args.rounds}", *args.overrides]
        ),
        "loop_ms_per_epoch": statistics.median(loop),
        "bare_ms_per_epoch": statistics.median(bare),
        "host_syncs_per_step_bare": syncs[0],
        "rounds": {"loop": loop, "bare": bare},
    }
    row["overhead_ms_per_epoch"] = row["loop_ms_per_epoch"] - row["bare_ms_per_epoch"]
    from gyrodenoise.atomic import write_json, write_text

    path = OUT.with_suffix(".json")
    rows = json.loads(path.read_text()) if path.is_file() else []
    rows.append(row)
    write_json(path, rows)
    write_text(OUT.with_suffix(".md"), report(rows))
    print(json.dumps({k: v for k, v in row.items() if k != "rounds"}, indent=1))


def report(rows: list[dict]) -> str:
    lines = [
        "# Per-epoch cost of the training loop around the network (issue 9)",
        "",
        "`python benchmarks/epoch_overhead.py` (docstring there): the EuRoC run with its arithmetic made "
        "negligible (`model.channels=[2,2,2,2] dataset.window=64`). loop: `gyrodenoise.train`, per-epoch wall "
        "from 200 vs 600 epochs; bare: the same step in a plain loop; medians over rounds. One row per "
        "measurement, oldest first.",
        "",
        "| code | device | machine | loop (ms/epoch) | bare (ms/epoch) | loop - bare | host syncs per step (bare) "
        "| command |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        s = r["host_syncs_per_step_bare"]
        lines.append(
            f"| {r['label']} | {r['device']} | {r['machine']} | {r['loop_ms_per_epoch']:.2f} | "
            f"{r['bare_ms_per_epoch']:.2f} | {r['overhead_ms_per_epoch']:.2f} | "
            f"{'n/a (CPU)' if s is None else f'{s:g}'} | `{r['command']}` |"
        )
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    main()
