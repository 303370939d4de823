"""Where one GPU training step of the default EuRoC run spends its time (issue 9's GPU line).

    python benchmarks/gpu_step_breakdown.py [--steps 30] [--device cuda|cpu]

One epoch is one optimiser step (6 crops x 9601 samples), so on a GPU the step's wall time is the epoch's. In one
process on the GPU this times, per step (CUDA synchronised before and after, medians of `--steps` steps after
warm-up):
- the batch: drawing the crops on the CPU (the datamodule's loader) and copying them to the GPU;
- the step cut short: forward; + increment loss (float64); + backward; + Adam (torch's default, foreach);
- the whole step with Adam fused (`fused=True`), with cudnn.benchmark, and back to back (no synchronisation
  between steps: the CPU may queue the next step while the GPU works);
- the whole step replayed as one CUDA graph (`gyrodenoise.cuda_graph_step`, the training's own: capturable Adam,
  the batch copied into static buffers): what the step costs when the CPU's launches are taken out;
and, under torch.profiler, the kernels launched per step, the GPU's busy time per step and the top kernels.
If the GPU's busy time is far below the wall time, the step is bound by the CPU's launches, not the arithmetic.
Writes benchmarks/results/gpu_step_breakdown.{md,json}. Needs a CUDA device and ../shared/data/euroc (or
GYRODENOISE_DATA); `--device cpu` runs the same code paths on the CPU (no graph, no profile; checks the script
without a GPU, writes nothing).
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import torch

# a sibling module: run from the repository root as `python benchmarks/gpu_step_breakdown.py`
from cpu_step_profile import build

OUT = Path("benchmarks/results/gpu_step_breakdown")


def sync() -> None:
    if torch.cuda.is_available():
        torch.cuda.synchronize()


def timed(fn, steps: int, warmup: int = 3) -> list[float]:
    """Milliseconds of `fn()` per call, synchronised before and after each."""
    for _ in range(warmup):
        fn()
    sync()
    out = []
    for _ in range(steps):
        start = time.perf_counter()
        fn()
        sync()
        out.append(1e3 * (time.perf_counter() - start))
    return out


def back_to_back(fn, steps: int) -> float:
    """Milliseconds per call of `steps` calls queued without synchronisation between them."""
    fn()
    sync()
    start = time.perf_counter()
    for _ in range(steps):
        fn()
    sync()
    return 1e3 * (time.perf_counter() - start) / steps


def step_fns(module, opt, batch: dict) -> dict:
    def forward():
        return module.model(batch["imu"])

    def loss():
        return module.loss_fn(forward(), batch["dt"], batch["dR"], batch["dR_mask"])

    def backward():
        opt.zero_grad(set_to_none=True)
        loss().backward()

    def full():
        backward()
        opt.step()

    return {"forward": forward, "forward + loss": loss, "+ backward": backward, "+ Adam (whole step)": full}


def profile(fn, steps: int = 5) -> dict:
    from torch.profiler import ProfilerActivity

    fn()
    torch.cuda.synchronize()
    with torch.profiler.profile(activities=[ProfilerActivity.CPU, ProfilerActivity.CUDA]) as prof:
        for _ in range(steps):
            fn()
        torch.cuda.synchronize()
    kernels = [e for e in prof.events() if e.device_type == torch.autograd.DeviceType.CUDA]
    busy_us = sum(e.device_time for e in kernels) if kernels else 0.0
    table = prof.key_averages().table(sort_by="device_time_total", row_limit=15)
    return {"kernels_per_step": len(kernels) / steps, "gpu_busy_ms_per_step": busy_us / 1e3 / steps, "table": table}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--steps", type=int, default=30)
    ap.add_argument("--device", choices=("cuda", "cpu"), default="cuda")
    args = ap.parse_args()
    dev = args.device
    if dev == "cuda" and not torch.cuda.is_available():
        raise SystemExit("gpu_step_breakdown needs a CUDA device (torch.cuda.is_available() is False)")
    from gyrodenoise.atomic import write_json, write_text
    from gyrodenoise.provenance import git_revision, machine_description

    module, opt, cpu_batch = build()
    rows: dict[str, list[float]] = {}
    # the batch: the datamodule's crops on the CPU, then the copy to the GPU
    from hydra.utils import instantiate

    from gyrodenoise.config import compose_config

    cfg = compose_config("train", ["dataset=euroc"])
    dm = instantiate(cfg.dataset)
    dm.setup("fit")
    dm_loader = dm.train_dataloader()
    rows["batch: crops on the CPU"] = timed(lambda: next(iter(dm_loader)), args.steps)
    rows["batch: copy to the GPU"] = timed(lambda: {k: v.to(dev) for k, v in cpu_batch.items()}, args.steps)
    module.to(dev)
    batch = {k: v.to(dev) for k, v in cpu_batch.items()}
    fns = step_fns(module, opt, batch)
    for name, fn in fns.items():
        rows[name] = timed(fn, args.steps)
    full = fns["+ Adam (whole step)"]
    if dev == "cpu":  # the script's check without a GPU
        print({k: round(statistics.median(v), 2) for k, v in rows.items()})
        return 0
    prof_default = profile(full)
    back = {"whole step, back to back": back_to_back(full, args.steps)}
    fused = torch.optim.Adam(module.parameters(), lr=cfg.optim.lr, weight_decay=cfg.optim.weight_decay, fused=True)
    rows["whole step, Adam fused"] = timed(step_fns(module, fused, batch)["+ Adam (whole step)"], args.steps)
    torch.backends.cudnn.benchmark = True
    rows["whole step, cudnn.benchmark"] = timed(full, args.steps)
    torch.backends.cudnn.benchmark = False
    graph_error = None
    try:
        # the training's own graph step (gyrodenoise.cuda_graph_step), on a fresh Adam; calls 7-8 measured an
        # inline capture of the same step before that module existed
        from gyrodenoise.cuda_graph_step import GraphedTrainingStep

        adam = torch.optim.Adam(module.parameters(), lr=cfg.optim.lr, weight_decay=cfg.optim.weight_decay)
        graphed = GraphedTrainingStep(module, adam)

        def replay():
            return graphed(batch)

        rows["whole step, one CUDA graph"] = timed(replay, args.steps)
        back["CUDA graph, back to back"] = back_to_back(replay, args.steps)
        prof_graph = profile(replay)
    except Exception as exc:  # noqa: BLE001 - recorded: a capture that fails is a finding, not a crash
        graph_error, prof_graph = f"{type(exc).__name__}: {exc}", None

    rev = git_revision(Path.cwd())
    code = f"{rev[0]}{'-dirty' if rev[1] else ''}" if rev else "unknown (no git checkout on this machine)"
    machine = machine_description()
    command = f"python benchmarks/gpu_step_breakdown.py --steps {args.steps}"
    med = {k: statistics.median(v) for k, v in rows.items()}
    write_json(
        OUT.with_suffix(".json"),
        {
            "command": command,
            "machine": machine,
            "code": code,
            "ms": rows,
            "back_to_back_ms": back,
            "profile": prof_default,
            "profile_graph": prof_graph,
            "graph_error": graph_error,
        },
    )
    md = [
        "# One GPU training step of the default EuRoC run, taken apart",
        "",
        f"`{command}` on {machine}, code {code}, nothing else running. Medians over {args.steps} steps",
        "(CUDA synchronised around each), quartiles in brackets; 'back to back': steps queued without a",
        "synchronisation between them. See the script's docstring.",
        "",
        "| part | ms per step |",
        "|---|---|",
    ]
    for k, v in rows.items():
        q = statistics.quantiles(v, n=4)
        md.append(f"| {k} | {med[k]:.2f} ({q[0]:.2f} - {q[2]:.2f}) |")
    md += [f"| {k} | {v:.2f} |" for k, v in back.items()]
    md += [
        "",
        f"Under torch.profiler (eager whole step): {prof_default['kernels_per_step']:.0f} kernels per step, GPU busy",
        f"{prof_default['gpu_busy_ms_per_step']:.2f} ms per step.",
    ]
    if prof_graph:
        md.append(f"As one CUDA graph: GPU busy {prof_graph['gpu_busy_ms_per_step']:.2f} ms per step.")
    if graph_error:
        md.append(f"CUDA graph capture failed: {graph_error}")
    md += ["", "Top kernels (eager whole step, 5 steps):", "", "```", prof_default["table"], "```", ""]
    write_text(OUT.with_suffix(".md"), "\n".join(md))
    print("\n".join(md))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
