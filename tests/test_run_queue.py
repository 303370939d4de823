"""Several trainings at once on one machine (benchmarks/run_queue.py): all run, summaries are
collected, a failing run is reported without stopping the others, and a rerun skips what is done."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from _asl import write_asl_sequence

REPO = Path(__file__).resolve().parents[1]


def test_queue_runs_two_at_once_and_resumes(tmp_path):
    root = tmp_path / "asl"
    for i, name in enumerate(["a", "b", "c"]):
        write_asl_sequence(root / name, seconds=6.0, seed=i)
    common = (
        f"dataset=euroc dataset.root={root} dataset.train_seqs=[a,b] dataset.test_seqs=[c] "
        "dataset.train_duration_s=4 "
        "dataset.window=256 dataset.gt_files={} dataset.eval_gt_variants={} model.channels=[4,8] model.dilations=[1,2] "
        "trainer.max_epochs=2 trainer.check_val_every_n_epoch=1 trainer.accelerator=cpu optim.scheduler.T_0=2 "
        "logger=none"
    )
    queue = tmp_path / "queue.txt"
    queue.write_text(
        f"# two good runs and a bad one\nruns/s0 {common} seed=0\nruns/s1 {common} seed=1\n"
        f"runs/bad {common} model.act=nope\n"
    )
    cmd = [sys.executable, str(REPO / "benchmarks" / "run_queue.py"), str(queue), "--jobs", "2", "--threads", "1"]
    cmd += ["--out", str(tmp_path / "out"), "--collect", str(tmp_path / "collect"), "--note", "two at once"]
    env = {**os.environ, "PYTHONWARNINGS": "ignore"}
    proc = subprocess.run(cmd, capture_output=True, text=True, cwd=tmp_path, env=env, timeout=300)
    assert proc.returncode == 1, proc.stdout + proc.stderr  # the bad run fails the queue...
    assert "FAILED runs/bad" in proc.stdout and "model.act='nope'" in proc.stdout  # ...with its log's tail
    for seed in (0, 1):  # ...but not the good ones
        s = json.loads((tmp_path / "collect" / "runs" / f"s{seed}.json").read_text())
        assert s["seed"] == seed and s["queue"]["threads"] == 1 and s["queue"]["process_wall_time_s"] > 0
        assert s["queue"]["note"] == "two at once"
        assert f"seed={seed}" in s["overrides"] and s["test"]["test/aoe_deg"] > 0
    assert "2 runs finished" in proc.stdout
    again = subprocess.run(cmd, capture_output=True, text=True, cwd=tmp_path, env=env, timeout=300)
    assert "1 runs to do" in again.stdout  # only the failed one is tried again


def test_shards_split_a_queue_without_overlap(tmp_path):
    sys.path.insert(0, str(REPO / "benchmarks"))
    import run_queue

    queue = tmp_path / "q.txt"
    queue.write_text("".join(f"r{i} seed={i}\n" for i in range(7)))
    runs = run_queue.read_queue(queue)
    shards = [runs[k::n] for k, n in (run_queue._shard("0/3"), run_queue._shard("1/3"), run_queue._shard("2/3"))]
    ids = [r for s in shards for r, _ in s]
    assert sorted(ids) == sorted(r for r, _ in runs) and len(ids) == len(set(ids)) == 7
    for bad in ("3/3", "a/2", "1"):
        with pytest.raises(SystemExit, match="--shard"):
            run_queue._shard(bad)


def test_a_claimed_run_is_skipped_and_a_dead_runners_claim_taken_over(tmp_path):
    sys.path.insert(0, str(REPO / "benchmarks"))
    import socket

    import run_queue

    claim = run_queue._claim(tmp_path, "runs/a")
    assert claim is not None and (claim / "owner").read_text() == f"{socket.gethostname()} {os.getpid()}"
    assert run_queue._claim(tmp_path, "runs/a") is None  # held by a live runner (this one)
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    (claim / "owner").write_text(f"{socket.gethostname()} {int(dead.stdout)}")
    assert run_queue._claim(tmp_path, "runs/a") == claim  # its runner is gone: taken over
