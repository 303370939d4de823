"""Do torch.compile or bfloat16 autocast make a training step of the default EuRoC run faster, at what cost?

    python benchmarks/step_variants.py [--rounds 2] [--steps 12] [--threads 2] [--device cpu|cuda]

One training step of `dataset=euroc` (the real batch: 6 crops of 9601 samples; forward, increment loss in
float64, backward, Adam) in fresh processes of five kinds, alternating for `--rounds` rounds:
  eager     the training default (on the CPU: the input gradient of the dilated convolutions as a forward
            convolution, numpy dropout masks; gyrodenoise.models.cpu_layers)
  loss      torch.compile of the increment loss only (the float64 SO(3) products), the network eager
  net       torch.compile of the network (inside it those two CPU layers are torch's own, which the compiler
            traces), loss eager
  net+loss  torch.compile of the network and the increment loss together
  bf16      the network's forward under torch.autocast(bfloat16) (mixed precision), loss float64 as always
Per kind: the first step (compilation included), the median of the timed steps after 3 warm-up steps, and the
break-even number of steps (compile time over the per-step saving). Parity, in one process, with dropout off so
that both paths compute the same function: the loss and the gradient of every parameter, each kind vs eager.
Writes benchmarks/results/step_variants{_<device>}.{md,json}. Needs ../shared/data/euroc (or GYRODENOISE_DATA).
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

# a sibling module: run from the repository root as `python benchmarks/step_variants.py`
from cpu_step_profile import alternate, build

OUT = Path("benchmarks/results/step_variants")
KINDS = ("eager", "loss", "net", "net+loss", "bf16")


def step_function(module, kind: str):
    """A callable (batch) -> loss for one kind; a compiled kind compiles at its first call."""
    import torch

    def loss_of(batch: dict) -> torch.Tensor:
        w_hat = module.model(batch["imu"])
        return module.loss_fn(w_hat, batch["dt"], batch["dR"], batch["dR_mask"])

    if kind == "eager":
        return loss_of
    if kind == "loss":
        loss_fn = torch.compile(module.loss_fn)
        return lambda b: loss_fn(module.model(b["imu"]), b["dt"], b["dR"], b["dR_mask"])
    if kind == "bf16":

        def mixed(batch: dict) -> torch.Tensor:
            with torch.autocast(batch["imu"].device.type, dtype=torch.bfloat16):
                w_hat = module.model(batch["imu"])
            return module.loss_fn(w_hat.float(), batch["dt"], batch["dR"], batch["dR_mask"])

        return mixed
    if kind == "net":
        net = torch.compile(module.model)
        return lambda b: module.loss_fn(net(b["imu"]), b["dt"], b["dR"], b["dR_mask"])
    return torch.compile(loss_of)


def sync(device: str) -> None:
    import torch

    if device == "cuda":
        torch.cuda.synchronize()


def timed_step(fn, opt, batch: dict, device: str) -> float:
    sync(device)
    start = time.perf_counter()
    opt.zero_grad()
    fn(batch).backward()
    opt.step()
    sync(device)
    return time.perf_counter() - start


def to_device(module, batch: dict, device: str) -> dict:
    import torch

    module.to(device)
    return {k: v.to(device) if isinstance(v, torch.Tensor) else v for k, v in batch.items()}


def child(kind: str, steps: int, threads: int, device: str) -> None:
    import torch

    from gyrodenoise.cpu_memory import retain_freed_memory

    retain_freed_memory()
    torch.set_num_threads(threads)
    module, opt, batch = build()
    batch = to_device(module, batch, device)  # the parameters move in place: Adam keeps them (its state is lazy)
    fn = step_function(module, kind)
    first = timed_step(fn, opt, batch, device)
    for _ in range(2):  # warm-up: the rest of the recompilations, oneDNN primitives, allocator
        timed_step(fn, opt, batch, device)
    ms = [1e3 * timed_step(fn, opt, batch, device) for _ in range(steps)]
    print("RESULT " + json.dumps({"kind": kind, "first_s": first, "ms": ms}))


def parity(device: str) -> dict:
    """Loss and parameter gradients of each kind against eager, dropout off, same weights and batch."""
    import torch

    module, _, batch = build()
    batch = to_device(module, batch, device)
    for m in module.modules():
        if isinstance(m, torch.nn.Dropout):
            m.p = 0.0
    out = {}
    ref_loss, ref_grads = None, None
    for kind in KINDS:
        module.zero_grad()
        loss = step_function(module, kind)(batch)
        loss.backward()
        grads = {n: p.grad.detach().double().clone() for n, p in module.named_parameters() if p.grad is not None}
        if kind == "eager":
            ref_loss, ref_grads = float(loss.detach()), grads
            continue
        rel = max(float((grads[n] - g).norm() / g.norm().clamp(min=1e-30)) for n, g in ref_grads.items())
        out[kind] = {"loss_rel_diff": abs(float(loss.detach()) - ref_loss) / abs(ref_loss), "max_grad_rel_diff": rel}
    return out


def run_child(kind: str, args: argparse.Namespace) -> dict:
    cmd = [sys.executable, __file__, "--child", kind, "--steps", str(args.steps), "--threads", str(args.threads)]
    with tempfile.TemporaryDirectory() as cache:  # a cold compile, as on a fresh machine: no cached kernels
        env = {**os.environ, "TORCHINDUCTOR_CACHE_DIR": cache, "TRITON_CACHE_DIR": cache}
        res = subprocess.run([*cmd, "--device", args.device], capture_output=True, text=True, env=env)
    if res.returncode != 0:
        raise SystemExit(f"{kind} process failed:\n{res.stderr[-3000:]}")
    line = next(ln for ln in res.stdout.splitlines() if ln.startswith("RESULT "))
    return json.loads(line[len("RESULT ") :])


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rounds", type=int, default=2, help="processes per kind (alternating)")
    ap.add_argument("--steps", type=int, default=12, help="timed steps per process")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--device", default="cpu", choices=("cpu", "cuda"))
    ap.add_argument("--epochs", type=int, default=600, help="fit length for the per-fit saving column")
    ap.add_argument("--child", choices=KINDS, help=argparse.SUPPRESS)
    args = ap.parse_args()
    import torch

    if args.device == "cuda" and not torch.cuda.is_available():
        raise SystemExit("--device cuda: this machine has no CUDA device (torch.cuda.is_available() is False)")
    if args.child:
        child(args.child, args.steps, args.threads, args.device)
        return 0
    from gyrodenoise.atomic import write_json, write_text
    from gyrodenoise.provenance import git_revision, machine_description

    runs = alternate(
        KINDS,
        args.rounds,
        lambda k: run_child(k, args),
        lambda res: f"first step {res['first_s']:.1f} s, median {statistics.median(res['ms']):.0f} ms",
    )
    torch.set_num_threads(args.threads)
    par = parity(args.device)
    med = {k: statistics.median([t for run in runs[k] for t in run["ms"]]) for k in KINDS}
    first = {k: statistics.median([run["first_s"] for run in runs[k]]) for k in KINDS}
    rows = []
    for k in KINDS:
        saving_ms = med["eager"] - med[k]
        extra_s = first[k] - first["eager"]
        per_fit = args.epochs * saving_ms / 1e3 - extra_s
        even = f"{extra_s / (saving_ms / 1e3):.0f}" if k != "eager" and saving_ms > 0 else "-"
        q = statistics.quantiles([t for run in runs[k] for t in run["ms"]], n=4)
        rows.append(
            f"| {k} | {first[k]:.1f} | {med[k]:.0f} | {q[0]:.0f} - {q[2]:.0f} | "
            f"{'-' if k == 'eager' else f'{saving_ms:+.0f}'} | {even} | {'-' if k == 'eager' else f'{per_fit:+.0f}'} |"
        )
    rev = git_revision(Path.cwd())
    command = (
        f"python benchmarks/step_variants.py --rounds {args.rounds} --steps {args.steps} --threads {args.threads} "
        f"--device {args.device}"
    )
    machine = f"{machine_description()}, {args.threads} threads used"
    par_rows = [f"| {k} | {v['loss_rel_diff']:.1e} | {v['max_grad_rel_diff']:.1e} |" for k, v in par.items()]
    md = [
        f"# torch.compile, bfloat16 autocast and one training step of the default EuRoC run ({args.device})",
        "",
        f"`{command}` on {machine}, nothing else running; code {rev[0] if rev else 'unknown'}"
        f"{'-dirty' if rev and rev[1] else ''}. Fresh processes per kind, kinds alternating over {args.rounds} rounds;",
        "medians over all timed steps. 'first step' includes the compilation (a cold one: each process has an empty",
        "inductor cache, as on a fresh machine; a second run on the same machine reuses the cache); 'break-even' is",
        f"the number of steps after which the compile time is paid back; 'per {args.epochs}-epoch fit' is the saving",
        "of one default fit (one step per epoch) net of the compile time (positive: faster).",
        "",
        f"| kind | first step (s) | median step (ms) | quartiles (ms) | saving per step (ms) | break-even (steps) "
        f"| per {args.epochs}-epoch fit (s) |",
        "|---|---|---|---|---|---|---|",
        *rows,
        "",
        "Parity (dropout off, same weights and batch; relative to eager): the loss, and the largest relative",
        "difference of a parameter's gradient (norm of the difference over the norm).",
        "",
        "| kind | loss | gradient |",
        "|---|---|---|",
        *par_rows,
    ]
    out = OUT if args.device == "cpu" else OUT.with_name(f"{OUT.name}_{args.device}")
    write_json(
        out.with_suffix(".json"),
        {"command": command, "machine": machine, "node": platform.node(), "runs": runs, "parity": par},
    )
    write_text(out.with_suffix(".md"), "\n".join(md) + "\n")
    print("\n".join(md))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
