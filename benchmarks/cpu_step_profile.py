"""What one CPU training step of the default EuRoC run costs, and what two CPU measures save.

    python benchmarks/cpu_step_profile.py [--rounds 4] [--steps 15] [--threads 2]

One training step of `dataset=euroc` (the real batch: 6 crops of 9601 samples; forward, increment
loss, backward, Adam) is timed in fresh processes of four kinds: the training default (freed memory
retained, `gyrodenoise.cpu_memory`; dilated convolutions' input gradient as a forward convolution,
`gyrodenoise.models.cpu_layers.DilatedConv1d`), the default without the convolution measure (torch's
backward), the default under glibc's default malloc, and neither measure (the code before them).
The kinds alternate for `--rounds` rounds (the order rotating), so that a slower or faster spell of
a shared VM hits all; figures are medians over all timed steps, with the minor page faults per step.
Then torch's profiler lists the operators of a default step. Writes
benchmarks/results/cpu_step_profile.{md,json}. Needs ../shared/data/euroc (or GYRODENOISE_DATA).
"""

from __future__ import annotations

import argparse
import json
import platform
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

OUT = Path("benchmarks/results/cpu_step_profile")
MODES = ("default", "torch_conv_backward", "glibc_malloc", "neither")
NAMES = {
    "default": "training default (retained memory, input gradient as a convolution)",
    "torch_conv_backward": "retained memory, torch's convolution backward",
    "glibc_malloc": "glibc's default malloc, input gradient as a convolution",
    "neither": "neither measure (glibc's malloc, torch's backward)",
}


def build():
    import torch
    from hydra.utils import instantiate

    from gyrodenoise.config import compose_config
    from gyrodenoise.lit import DenoiserModule

    cfg = compose_config("train", ["dataset=euroc"])
    dm = instantiate(cfg.dataset)
    dm.setup("fit")
    module = DenoiserModule.from_config(cfg)
    module.model.set_normalization(*dm.normalization())
    opt = torch.optim.Adam(module.parameters(), lr=cfg.optim.lr, weight_decay=cfg.optim.weight_decay)
    torch.manual_seed(0)
    return module, opt, next(iter(dm.train_dataloader()))


def alternate(kinds: tuple[str, ...], rounds: int, run_one, describe) -> dict[str, list[dict]]:
    """`rounds` fresh processes per kind, `run_one(kind)` each, the kinds' order rotating from round to round
    so that a slower or faster spell of a shared machine hits all kinds; prints `describe(result)` per process."""
    runs: dict[str, list[dict]] = {k: [] for k in kinds}
    for r in range(rounds):
        for kind in kinds[r % len(kinds) :] + kinds[: r % len(kinds)]:
            runs[kind].append(run_one(kind))
            print(f"round {r} {kind}: {describe(runs[kind][-1])}", flush=True)
    return runs


def step(module, opt, batch: dict) -> tuple[float, int]:
    """Wall seconds and minor page faults of one optimiser step."""
    faults = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    start = time.perf_counter()
    opt.zero_grad()
    w_hat = module.model(batch["imu"])
    module.loss_fn(w_hat, batch["dt"], batch["dR"], batch["dR_mask"]).backward()
    opt.step()
    return time.perf_counter() - start, resource.getrusage(resource.RUSAGE_SELF).ru_minflt - faults


def child(mode: str, steps: int, threads: int, profile: bool) -> None:
    import torch

    from gyrodenoise.cpu_memory import retain_freed_memory
    from gyrodenoise.models.cpu_layers import DilatedConv1d

    applied = retain_freed_memory() if mode not in ("glibc_malloc", "neither") else False
    DilatedConv1d.input_grad_as_conv = mode not in ("torch_conv_backward", "neither")
    torch.set_num_threads(threads)
    module, opt, batch = build()
    for _ in range(3):  # warm-up: oneDNN primitives, allocator
        step(module, opt, batch)
    timed = [step(module, opt, batch) for _ in range(steps)]
    out = {"mode": mode, "applied": applied, "ms": [1e3 * t for t, _ in timed], "faults": [f for _, f in timed]}
    if profile:
        with torch.profiler.profile(activities=[torch.profiler.ProfilerActivity.CPU]) as prof:
            for _ in range(5):
                step(module, opt, batch)
        out["profile"] = prof.key_averages().table(sort_by="self_cpu_time_total", row_limit=15)
    print("RESULT " + json.dumps(out))


def run_child(mode: str, args: argparse.Namespace, profile: bool = False) -> dict:
    cmd = [sys.executable, __file__, "--child", mode, "--steps", str(args.steps), "--threads", str(args.threads)]
    res = subprocess.run(cmd + (["--profile"] if profile else []), capture_output=True, text=True, check=True)
    line = next(ln for ln in res.stdout.splitlines() if ln.startswith("RESULT "))
    return json.loads(line[len("RESULT ") :])


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rounds", type=int, default=4, help="processes per mode (alternating)")
    ap.add_argument("--steps", type=int, default=15, help="timed steps per process")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--child", choices=MODES, help=argparse.SUPPRESS)
    ap.add_argument("--profile", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        child(args.child, args.steps, args.threads, args.profile)
        return 0
    import torch

    from gyrodenoise.atomic import write_json, write_text

    runs = alternate(
        MODES, args.rounds, lambda m: run_child(m, args), lambda res: f"median {statistics.median(res['ms']):.0f} ms"
    )
    profile = run_child("default", args, profile=True)["profile"]
    ms = {m: [t for run in runs[m] for t in run["ms"]] for m in MODES}
    faults = {m: statistics.median([f for run in runs[m] for f in run["faults"]]) for m in MODES}
    med = {m: statistics.median(v) for m, v in ms.items()}
    machine = f"{platform.node()} ({platform.machine()}, {args.threads} threads, torch {torch.__version__})"
    command = (
        f"python benchmarks/cpu_step_profile.py --rounds {args.rounds} --steps {args.steps} --threads {args.threads}"
    )
    write_json(OUT.with_suffix(".json"), {"command": command, "machine": machine, "runs": runs})
    quart = {m: statistics.quantiles(v, n=4) for m, v in ms.items()}
    per_round = {m: ", ".join(f"{statistics.median(run['ms']):.0f}" for run in runs[m]) for m in MODES}
    md = [
        "# One CPU training step of the default EuRoC run",
        "",
        f"`{command}` on {machine}, nothing else running. Batch: 6 crops x 9601 samples; forward, increment",
        "loss (float64), backward, Adam. Fresh processes, the kinds in rotating order; medians over all timed",
        "steps, quartiles, the median of each process, and the minor page faults per step.",
        "",
        "| process | median step (ms) | quartiles (ms) | per process (ms) | page faults per step |",
        "|---|---|---|---|---|",
        *(
            f"| {NAMES[m]} | {med[m]:.0f} | {quart[m][0]:.0f} - {quart[m][2]:.0f} | {per_round[m]} | {faults[m]:.0f} |"
            for m in MODES
        ),
        "",
        *(
            f"- {what}: {med[m] - med['default']:.0f} ms per step ({100 * (med[m] - med['default']) / med[m]:.0f}%), "
            f"{0.6 * (med[m] - med['default']):.0f} s of a 600-epoch fit"
            for m, what in (
                ("glibc_malloc", "retained memory saves"),
                ("torch_conv_backward", "the convolution measure saves"),
                ("neither", "both save"),
            )
        ),
        "",
        "Operators of a default step (torch profiler, 5 steps):",
        "",
        "```",
        profile,
        "```",
        "",
    ]
    write_text(OUT.with_suffix(".md"), "\n".join(md))
    print("\n".join(md[:15]))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
