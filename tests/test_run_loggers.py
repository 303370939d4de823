"""What a training sends to MLflow (logger=mlflow) and TensorBoard together: curves, figures, settings, final
figures and the run's files, checked by reading the MLflow store back (tiny synthetic data, one epoch)."""

from __future__ import annotations

import json
import os

import pytest
from _asl import TINY_TRAINING, run_train

mlflow = pytest.importorskip("mlflow", reason="logger=mlflow needs the [mlflow] extra (in [dev])")


@pytest.mark.parametrize("backend", ["file", "sqlite"])
def test_a_run_logs_curves_figures_settings_and_files_to_mlflow_beside_tensorboard(
    tiny_asl_root, tmp_path, monkeypatch, backend
):
    if backend == "sqlite":  # MLflow's database store (what its server and newer versions default to)
        pytest.importorskip("sqlalchemy", reason="MLflow's sqlite store needs sqlalchemy and alembic")
        pytest.importorskip("alembic", reason="MLflow's sqlite store needs sqlalchemy and alembic")
    store = f"file:{tmp_path / 'mlruns'}" if backend == "file" else f"sqlite:///{tmp_path / 'mlflow.db'}"
    monkeypatch.setenv("MLFLOW_TRACKING_URI", store)
    args = [
        "dataset=asl_folder",
        f"dataset.root={tiny_asl_root}",
        "dataset.train_seqs=[a,b]",
        "dataset.test_seqs=[c]",
        *[a for a in TINY_TRAINING if not a.startswith("logger=")],
        "logger=[tensorboard,mlflow]",
        "seed=3",
        "trainer.max_epochs=2",  # a validation inside the fit each epoch: its curve and figures
        "trainer.check_val_every_n_epoch=1",
        "trainer.log_every_n_steps=1",
        "optim.scheduler.T_0=2",
        f"hydra.run.dir={tmp_path / 'run'}",
    ]
    run_train(args, cwd=tmp_path)
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert list((tmp_path / "run" / "tensorboard").glob("events.out.tfevents.*"))  # both loggers ran

    client = mlflow.tracking.MlflowClient(tracking_uri=store)
    (experiment,) = [e for e in client.search_experiments() if e.name == "train-asl_folder"]
    (run,) = client.search_runs([experiment.experiment_id])
    assert run.info.run_name == "denoiser-seed3" and run.info.status == "FINISHED"
    assert run.data.tags["output_dir"] == str(tmp_path / "run")
    params = run.data.params
    assert params["seed"] == "3" and params["dataset/name"] == "asl_folder"
    assert params["model/channels"] == "[4, 8]" and params["optim/lr"] == "0.01"  # the module's, by Lightning
    assert params["trainer/max_epochs"] == "2" and not [k for k in params if "." in k]  # one separator: /
    metrics = run.data.metrics  # the last value of each curve, and the run's final figures
    assert metrics["test/aoe_deg"] == pytest.approx(summary["test"]["test/aoe_deg"])
    assert metrics["selected_val/aoe_deg"] == pytest.approx(summary["val"]["val/aoe_deg"])
    assert len(client.get_metric_history(run.info.run_id, "val/aoe_deg")) == 2
    assert metrics["test/aoe_deg.c"] == pytest.approx(summary["test"]["test/aoe_deg/c"])  # a sequence's figure
    # a validation tail a[4s:] by a name MLflow holds (Lightning stripped its brackets and colon: a4s)
    assert {"val/aoe_deg.a_after4s", "val/aoe_deg.b_after4s"} <= set(metrics)
    assert client.get_metric_history(run.info.run_id, "train/loss")
    files = {a.path for a in client.list_artifacts(run.info.run_id)}
    assert {"summary.json", "model.pt", "calibrated.pt", "train.log", "figures"} <= files
    figures = [a.path for d in client.list_artifacts(run.info.run_id, "figures/val") for a in [d]]
    assert sorted(os.path.basename(f) for f in figures) == ["gyro_correction", "orientation", "orientation_error"]
    pngs = client.list_artifacts(run.info.run_id, "figures/val/orientation")
    assert pngs and all(p.path.endswith(".png") for p in pngs)


def test_a_fold_is_named_and_a_resumed_folder_goes_on_in_its_unfinished_mlflow_run(tmp_path):
    from gyrodenoise.run_loggers import MLflowRunLogger

    store = f"file:{tmp_path / 'mlruns'}"
    kw = {"experiment_name": "train-mine", "run_name": "denoiser-seed0", "tracking_uri": store}
    first = MLflowRunLogger(fold=2, tags={"output_dir": "/runs/a"}, **kw)
    first.log_metrics({"train/loss": 1.0}, step=1)  # the run starts; interrupted: never finalized
    client = mlflow.tracking.MlflowClient(tracking_uri=store)
    assert client.get_run(first.run_id).info.run_name == "denoiser-seed0-fold2"
    again = MLflowRunLogger(fold=2, tags={"output_dir": "/runs/a"}, **kw)  # auto_resume in the same folder
    assert again.run_id == first.run_id
    other = MLflowRunLogger(fold=2, tags={"output_dir": "/runs/b"}, **kw)  # another folder: a run of its own
    assert other.run_id != first.run_id
    again.finalize("success")
    assert MLflowRunLogger(tags={"output_dir": "/runs/a"}, **kw).run_id != first.run_id  # a finished run is not reused


_start_together = None  # a barrier the forked jobs wait at, so that all of them look the experiment up at once


def _wait_here(barrier) -> None:
    global _start_together
    _start_together = barrier


def _start_run(store: str, name: str) -> str:
    from gyrodenoise.run_loggers import MLflowRunLogger

    _start_together.wait()
    return MLflowRunLogger(experiment_name=name, run_name="job", tracking_uri=store).run_id


def test_sweep_jobs_started_together_share_one_experiment(tmp_path):
    """The joblib launcher starts jobs at once in a fresh store: each must find the one experiment, not make its own.
    (Forked, not spawned: the race is in the store, and six fresh interpreters importing the package cost ~60 s.)"""
    import multiprocessing

    import gyrodenoise.run_loggers  # noqa: F401  (imported once here, not in each forked job)

    store = f"file:{tmp_path / 'mlruns'}"
    fork = multiprocessing.get_context("fork")
    client = mlflow.tracking.MlflowClient(tracking_uri=store)
    for name in ("train-a", "train-b", "train-c"):  # without the lock, each round splits its runs about half the time
        with fork.Pool(6, initializer=_wait_here, initargs=(fork.Barrier(6),)) as pool:
            runs = pool.starmap(_start_run, [(store, name)] * 6)
        (experiment,) = [e for e in client.search_experiments() if e.name == name]
        assert sorted(r.info.run_id for r in client.search_runs([experiment.experiment_id])) == sorted(runs)
