"""Running many jobs on a cluster: a requeued run resumes from its own checkpoint, jobs that fill the same cache do
not break each other, a cache that cannot be written does not stop a run, and bad settings end in one line."""

from __future__ import annotations

import os
import shutil
import time

import numpy as np
import pytest
from test_train import tiny_dataset

from gyrodenoise.cli_errors import ConfigError
from gyrodenoise.config import compose_config
from gyrodenoise.data.cache import load_sequence
from gyrodenoise.sim import handheld_trajectory, simulate_imu, write_asl
from gyrodenoise.train import _resume_point, build_module


def test_a_run_folder_resumes_from_its_newest_checkpoint_unless_finished(tmp_path):
    assert _resume_point(tmp_path) is None
    (tmp_path / "checkpoints").mkdir()
    last = tmp_path / "checkpoints" / "last.ckpt"
    shutil.make_archive(str(last.with_suffix("")), "zip", tmp_path, "checkpoints")  # a readable zip, as torch saves
    os.replace(last.with_suffix(".zip"), last)
    assert _resume_point(tmp_path) == last
    hpc = tmp_path / "hpc_ckpt_1.ckpt"  # Lightning's SLURM auto-requeue, written later
    shutil.copy(last, hpc)
    os.utime(hpc, (time.time() + 10, time.time() + 10))
    assert _resume_point(tmp_path) == hpc
    shutil.copy(last, tmp_path / "checkpoints" / "interrupted.ckpt")  # written at an interruption, newest
    os.utime(tmp_path / "checkpoints" / "interrupted.ckpt", (time.time() + 20, time.time() + 20))
    assert _resume_point(tmp_path) == tmp_path / "checkpoints" / "interrupted.ckpt"
    (tmp_path / "checkpoints" / "junk.ckpt").write_text("not a zip")
    (tmp_path / "model.pt").write_bytes(b"")  # finished: a rerun in its folder starts nothing from it
    assert _resume_point(tmp_path) is None


def test_a_sequence_written_by_another_job_meanwhile_is_kept(tmp_path):
    sim = simulate_imu(handheld_trajectory(2.0, seed=1), [], seed=1)
    first = write_asl(tmp_path / "seq", sim)
    stamp = (first / "mav0" / "imu0" / "data.csv").stat().st_mtime_ns
    assert write_asl(tmp_path / "seq", sim, keep_existing=True) == first
    assert (first / "mav0" / "imu0" / "data.csv").stat().st_mtime_ns == stamp  # not removed under a reader
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".seq.tmp")]  # its own copy cleaned up
    assert os.stat(first).st_mode & 0o055  # readable by others sharing the cache (mkdtemp makes 0700)


def test_a_cache_that_cannot_be_written_warns_and_the_run_goes_on(tiny_asl_root, tmp_path):
    blocked = tmp_path / "a_file"
    blocked.write_text("")  # a cache folder that cannot be created (works as root too, unlike chmod)
    with pytest.warns(UserWarning, match="cannot write the cache"):
        seq = load_sequence(tiny_asl_root, "a", cache_dir=blocked / "cache")
    assert np.isfinite(seq.gyro).all() and len(seq) > 100


def test_a_crop_window_the_loss_cannot_cut_ends_in_one_line(tiny_asl_root):
    cfg = compose_config("train", [*tiny_dataset(tiny_asl_root), "dataset.window=250"])
    with pytest.raises(ConfigError, match=r"dataset.window=250 is not a multiple .* \(32 samples\).*224 or 256"):
        build_module(cfg)


def test_slurm_jobs_take_their_thread_count_from_the_allocation(monkeypatch):
    assert compose_config("train", []).threads is None
    monkeypatch.setenv("SLURM_CPUS_PER_TASK", "3")
    assert compose_config("train", []).threads == 3


def test_scoring_after_a_requeue_scores_the_weights_given_not_lightnings_hpc_checkpoint(
    tiny_asl_root, tmp_path, monkeypatch
):
    """Under SLURM, a trainer without ckpt_path restores <default_root_dir>/hpc_ckpt_N.ckpt (auto-requeue): the
    post-fit scoring must not, or a requeued run would save and score an older epoch's weights as its final ones."""
    import hydra
    import torch
    from test_train import config

    from gyrodenoise.train import _score_without_callbacks, train

    train(config(tiny_asl_root, tmp_path / "old", "seed=1", "callbacks.last_checkpoint.every_n_epochs=1"))
    out = tmp_path / "new"
    out.mkdir()
    shutil.copy(tmp_path / "old" / "checkpoints" / "last.ckpt", out / "hpc_ckpt_1.ckpt")
    monkeypatch.setenv("SLURM_NTASKS", "1")
    monkeypatch.setenv("SLURM_JOB_NAME", "train")
    cfg = config(tiny_asl_root, out, "seed=2")
    module = build_module(cfg)
    before = {k: v.clone() for k, v in module.state_dict().items()}
    _score_without_callbacks(cfg, hydra.utils.instantiate(cfg.dataset), module)
    assert all(torch.equal(before[k], v) for k, v in module.state_dict().items())
