"""Operators and CPU time of one default EuRoC training step, code revision against code revision.

    python benchmarks/step_operators.py REV [REV ...] [--rounds 4] [--steps 15] [--threads 2]

REV is a git revision (checked out into a temporary worktree) or `.` (the working tree). For each, fresh
processes with that revision's package first on the path run the step of `cpu_step_profile.py` (6 crops x
9601 samples: forward, increment loss in float64, backward, Adam) and report:
- the operators one step dispatches (torch profiler: top-level aten operators that compute or copy, views
  left out). Each is a kernel launch and a round of Python/dispatcher work on a GPU, where the step's
  arithmetic is small; the count does not depend on the machine;
- the same for the loss alone (forward and backward);
- the CPU wall time of the whole step and of the loss alone (medians over all timed steps; the revisions
  alternate over `--rounds` rounds, the order rotating, so that a slow spell of a shared machine hits all).
Writes benchmarks/results/step_operators.{md,json}. Needs ../shared/data/euroc (or GYRODENOISE_DATA).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from cpu_step_profile import alternate, build, step

OUT = Path("benchmarks/results/step_operators")
# operators that only describe memory (views, metadata, allocation): not kernels
NOT_KERNELS = {
    "aten::" + n
    for n in (
        "as_strided select slice view unsqueeze reshape expand narrow squeeze t transpose permute unbind "
        "unflatten flatten alias _reshape_alias detach resolve_conj resolve_neg empty empty_strided empty_like "
        "to lift_fresh result_type _unsafe_view view_as split chunk contiguous broadcast_tensors "
        "is_nonzero item _local_scalar_dense matmul"
    ).split()
}  # matmul: its bmm / mm is counted instead


def count_kernels(fn) -> int:
    import torch

    with torch.profiler.profile(activities=[torch.profiler.ProfilerActivity.CPU]) as prof:
        fn()

    def top(e) -> bool:  # an operator not called by another counted one
        p = e.cpu_parent
        while p is not None:
            if p.name.startswith("aten::") and p.name not in NOT_KERNELS:
                return False
            p = p.cpu_parent
        return True

    return sum(1 for e in prof.events() if e.name.startswith("aten::") and e.name not in NOT_KERNELS and top(e))


def child(steps: int, threads: int) -> None:
    import torch

    from gyrodenoise.cpu_memory import retain_freed_memory

    retain_freed_memory()
    torch.set_num_threads(threads)
    module, opt, batch = build()
    w_hat = module.model(batch["imu"]).detach().requires_grad_()

    def loss_only() -> float:
        start = time.perf_counter()
        module.loss_fn(w_hat, batch["dt"], batch["dR"], batch["dR_mask"]).backward()
        w_hat.grad = None
        return time.perf_counter() - start

    for _ in range(3):  # warm-up: oneDNN primitives, allocator, Adam's state
        step(module, opt, batch)
        loss_only()
    out = {
        "step_ms": [1e3 * step(module, opt, batch)[0] for _ in range(steps)],
        "loss_ms": [1e3 * loss_only() for _ in range(steps)],
        "step_operators": count_kernels(lambda: step(module, opt, batch)),
        "loss_operators": count_kernels(loss_only),
        "torch": torch.__version__,
    }
    print("RESULT " + json.dumps(out))


def run_child(src: Path, args: argparse.Namespace) -> dict:
    env = dict(os.environ, PYTHONPATH=str(src))
    cmd = [sys.executable, __file__, "--child", "--steps", str(args.steps), "--threads", str(args.threads)]
    res = subprocess.run(cmd, capture_output=True, text=True, check=True, env=env)
    return json.loads(next(ln for ln in res.stdout.splitlines() if ln.startswith("RESULT "))[len("RESULT ") :])


def describe(rev: str) -> str:
    if rev == ".":
        head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "src"], capture_output=True, text=True).stdout.strip()
        return head + ("-dirty" if dirty else "")
    return subprocess.run(
        ["git", "rev-parse", "--short", rev], capture_output=True, text=True, check=True
    ).stdout.strip()


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("revs", nargs="*", help="git revisions, or . for the working tree")
    ap.add_argument("--rounds", type=int, default=4, help="processes per revision (alternating)")
    ap.add_argument("--steps", type=int, default=15, help="timed steps per process")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        child(args.steps, args.threads)
        return 0
    if not args.revs:
        ap.error("name at least one revision (e.g. HEAD~1 .)")
    from gyrodenoise.atomic import write_json, write_text

    labels = {rev: describe(rev) for rev in args.revs}
    with tempfile.TemporaryDirectory() as tmp:
        srcs = {}
        for rev in args.revs:
            if rev == ".":
                srcs[rev] = Path("src").resolve()
            else:
                tree = Path(tmp) / labels[rev]
                subprocess.run(["git", "worktree", "add", "--detach", str(tree), rev], check=True, capture_output=True)
                srcs[rev] = tree / "src"
        try:
            runs = alternate(
                tuple(args.revs),
                args.rounds,
                lambda rev: run_child(srcs[rev], args),
                lambda r: f"step {statistics.median(r['step_ms']):.0f} ms, {r['step_operators']} operators",
            )
        finally:
            for rev in args.revs:
                if rev != ".":
                    subprocess.run(["git", "worktree", "remove", "--force", str(srcs[rev].parent)], check=False)
    torch_version = runs[args.revs[0]][0]["torch"]
    machine = f"{platform.node()} ({platform.machine()}, {args.threads} threads, torch {torch_version})"
    command = (
        "python benchmarks/step_operators.py "
        + " ".join(args.revs)
        + (f" --rounds {args.rounds} --steps {args.steps} --threads {args.threads}")
    )
    write_json(OUT.with_suffix(".json"), {"command": command, "machine": machine, "labels": labels, "runs": runs})
    rows = []
    for rev in args.revs:
        step_ms = [t for r in runs[rev] for t in r["step_ms"]]
        loss_ms = [t for r in runs[rev] for t in r["loss_ms"]]
        step_ops = "/".join(str(n) for n in sorted({r["step_operators"] for r in runs[rev]}))
        loss_ops = "/".join(str(n) for n in sorted({r["loss_operators"] for r in runs[rev]}))
        per_process = ", ".join(f"{statistics.median(r['step_ms']):.0f}" for r in runs[rev])
        rows.append(
            f"| {labels[rev]} | {step_ops} | {loss_ops} | {statistics.median(step_ms):.0f} | {per_process} | "
            f"{statistics.median(loss_ms):.1f} |"
        )
    md = [
        "# Operators and CPU time of one default EuRoC training step, by code revision",
        "",
        f"`{command}` on {machine}. The step of `benchmarks/cpu_step_profile.py` (6 crops x 9601 samples; forward,",
        "increment loss in float64, backward, Adam); operators: top-level aten operators that compute or copy",
        "(views and allocations left out), i.e. the kernels a GPU would launch per step; times: medians over all",
        "timed steps of fresh processes, the revisions alternating (docstring of the script).",
        "",
        "| code | operators per step | of which the loss (forward + backward) | CPU step (ms) | per process (ms) "
        "| CPU loss forward + backward (ms) |",
        "|---|---|---|---|---|---|",
        *rows,
        "",
    ]
    write_text(OUT.with_suffix(".md"), "\n".join(md))
    print("\n".join(md))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
