"""Run a queue of trainings N at a time on one machine and collect their summary.json files.

    python benchmarks/run_queue.py benchmarks/queues/ablations.txt --jobs 8 --threads 2 --out runs/ --collect .

QUEUE has one run per line: `ID  override override ...` (blank lines and # comments skipped), e.g.
`reports/ablation_runs/activation/relu_s0  experiment=ablation_activation model.act=relu seed=0`. Each
run is `python -m gyrodenoise.train <overrides> hydra.run.dir=OUT/ID` with OMP_NUM_THREADS=threads,
its log in OUT/ID.log; when it finishes, its summary.json is copied to COLLECT/ID.json (atomically)
with the queue line and the process wall time added. Runs whose ID.json exists in COLLECT or in a
`--done` folder are skipped, so an interrupted queue resumes (IDs are paths: with `--collect .` the
summaries land where the reports read them). `--deadline S` starts no run after S seconds (a lease
on a borrowed GPU machine ends; what is finished is kept). Several runners may share one queue: each
claims a run before starting it (OUT/ID.claim, released when the run ends) and skips runs another live
runner holds; `--shard I/N` (every N-th line from line I) splits a queue between runners in advance.
A run that fails is reported with its log's tail and does not stop the queue. Works on a CPU-only
machine and on a GPU machine alike (the trainings pick the device); on one GPU, several processes
share it.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import socket
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor, as_completed
from pathlib import Path

from gyrodenoise.atomic import write_json


def read_queue(path: Path) -> list[tuple[str, list[str]]]:
    runs, seen = [], set()
    for lineno, line in enumerate(path.read_text().splitlines(), 1):
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        run_id, *overrides = line.split()
        if run_id in seen:
            raise ValueError(f"{path}:{lineno}: run id {run_id!r} appears twice")
        seen.add(run_id)
        runs.append((run_id, overrides))
    return runs


def run_one(
    run_id: str, overrides: list[str], out: Path, collect: Path, threads: int, note: str = "", jobs: int | None = None
) -> tuple[str, bool, float]:
    run_dir = out / run_id
    log = out / f"{run_id}.log"
    log.parent.mkdir(parents=True, exist_ok=True)
    env = {**os.environ, "OMP_NUM_THREADS": str(threads), "MKL_NUM_THREADS": str(threads)}
    cmd = [sys.executable, "-m", "gyrodenoise.train", *overrides, f"hydra.run.dir={run_dir}"]
    start = time.time()
    with open(log, "w") as fh:
        rc = subprocess.run(cmd, stdout=fh, stderr=subprocess.STDOUT, env=env).returncode
    wall = time.time() - start
    summary_file = run_dir / "summary.json"
    if rc != 0 or not summary_file.is_file():
        tail = log.read_text(errors="replace").splitlines()[-15:]
        print(f"FAILED {run_id} (exit {rc}, {wall:.0f} s):\n  " + "\n  ".join(tail), flush=True)
        return run_id, False, wall
    summary = json.loads(summary_file.read_text())
    summary["queue"] = {"id": run_id, "overrides": overrides, "process_wall_time_s": wall, "threads": threads}
    if jobs is not None:  # trainings this runner ran at once (other runners on the machine are not counted)
        summary["queue"]["jobs"] = jobs
    if note:
        summary["queue"]["note"] = note
    write_json(collect / f"{run_id}.json", summary)
    print(
        f"done {run_id} in {wall:.0f} s: test AOE {summary.get('test', {}).get('test/aoe_deg', float('nan')):.2f}",
        flush=True,
    )
    return run_id, True, wall


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("queue", type=Path, help="queue file: one 'ID override ...' line per run")
    ap.add_argument("--jobs", type=int, default=2, help="trainings at once (default: %(default)s)")
    ap.add_argument("--threads", type=int, default=1, help="CPU threads per training (default: %(default)s)")
    ap.add_argument("--out", type=Path, default=Path("runs"), help="run folders and logs (default: %(default)s)")
    ap.add_argument("--collect", type=Path, required=True, help="folder for the collected ID.json summaries")
    ap.add_argument("--done", type=Path, action="append", default=[], help="skip runs whose ID.json is here too")
    ap.add_argument("--deadline", type=float, default=None, help="start no run after this many seconds")
    ap.add_argument("--note", default="", help="recorded in each collected summary (e.g. how the machine was shared)")
    ap.add_argument(
        "--shard", default=None, help="I/N: only the runs at positions I, I+N, I+2N, ... of the queue (0-based)"
    )
    args = ap.parse_args(argv)
    runs = read_queue(args.queue)
    if args.shard:
        k, n = _shard(args.shard)
        runs = runs[k::n]
    todo = [(i, o) for i, o in runs if not _finished(i, args)]
    print(f"{len(todo)} runs to do, {args.jobs} at once, {args.threads} threads each", flush=True)
    start = time.time()
    failed, done = [], 0
    with ThreadPoolExecutor(args.jobs) as pool:
        futures = []
        for run_id, overrides in todo:
            futures.append(pool.submit(_guarded, run_id, overrides, args, start))
        for f in as_completed(futures):
            run_id, ok, _ = f.result()
            if ok is None:
                continue
            done += ok
            if not ok:
                failed.append(run_id)
    elapsed = time.time() - start
    print(
        f"{done} runs finished in {elapsed:.0f} s ({3600 * done / max(elapsed, 1e-9):.0f} runs/hour); failed: {failed}"
    )
    return 1 if failed else 0


def _finished(run_id: str, args: argparse.Namespace) -> bool:
    """Whether the run's summary is collected (in COLLECT or a --done folder)."""
    return any((d / f"{run_id}.json").is_file() for d in [args.collect, *args.done])


def _shard(text: str) -> tuple[int, int]:
    try:
        k, n = (int(x) for x in text.split("/"))
    except ValueError:
        raise SystemExit(f"--shard {text!r}: write I/N with integers, e.g. 0/2") from None
    if not 0 <= k < n:
        raise SystemExit(f"--shard {text!r}: I must be in 0..N-1")
    return k, n


def _claim(out: Path, run_id: str) -> Path | None:
    """Claim a run for this runner (an atomic mkdir of OUT/ID.claim holding 'host pid'), so that several
    runners can share one queue; None if a live runner holds it. A claim left by a runner of this host
    that is gone is taken over."""
    claim = out / f"{run_id}.claim"
    claim.parent.mkdir(parents=True, exist_ok=True)
    me = f"{socket.gethostname()} {os.getpid()}"
    try:
        claim.mkdir()
    except FileExistsError:
        try:
            host, pid = (claim / "owner").read_text().split()
        except (OSError, ValueError):
            return None  # being written by its owner right now
        if host != socket.gethostname() or _alive(int(pid)):
            return None
    (claim / "owner").write_text(me)
    return claim


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _guarded(
    run_id: str, overrides: list[str], args: argparse.Namespace, start: float
) -> tuple[str, bool | None, float]:
    if args.deadline is not None and time.time() - start > args.deadline:
        return run_id, None, 0.0  # past the deadline: not started
    if _finished(run_id, args):
        return run_id, None, 0.0  # finished by another runner meanwhile
    claim = _claim(args.out, run_id)
    if claim is None:
        print(f"skip {run_id}: another runner is on it ({args.out / run_id}.claim)", flush=True)
        return run_id, None, 0.0
    try:
        return run_one(run_id, overrides, args.out, args.collect, args.threads, args.note, args.jobs)
    finally:
        shutil.rmtree(claim, ignore_errors=True)


if __name__ == "__main__":
    raise SystemExit(main())
