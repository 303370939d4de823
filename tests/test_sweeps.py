"""Sweep configs: every experiment / hparams_search / launcher config composes, a two-point multirun
runs end to end on tiny synthetic data, and the ablation collector turns it into a table and a plot."""

from __future__ import annotations

import csv
import os
from pathlib import Path

import hydra
import numpy as np
import pytest
from _asl import run_train, write_asl_sequence
from hydra import compose, initialize_config_dir
from lightning.pytorch.callbacks import EMAWeightAveraging
from omegaconf import OmegaConf

from gyrodenoise import ablation
from gyrodenoise.config import CONF_DIR as CONF

EXPERIMENTS = sorted(p.stem for p in (CONF / "experiment").glob("*.yaml"))
SEARCHES = sorted(p.stem for p in (CONF / "hparams_search").glob("*.yaml"))
LAUNCHERS = sorted(p.stem for p in (CONF / "hydra" / "launcher").glob("*.yaml"))


def require_plugin(module: str) -> None:
    """Skip when an optional Hydra plugin is missing (pip install -e .[sweep,slurm]); fail under CI."""
    try:
        __import__(module)
    except ImportError:
        msg = f"{module} is not installed (pip install -e '.[sweep,slurm]')"
        if os.environ.get("CI", "").lower() == "true":
            pytest.fail(msg)
        pytest.skip(msg)


@pytest.fixture(scope="module", autouse=True)
def _hydra_conf():
    """One Hydra initialisation for all the compose calls of this module."""
    with initialize_config_dir(str(CONF), version_base="1.3"):
        yield


def compose_train(overrides: list[str]):
    return compose("train", overrides=overrides, return_hydra_config=True)


def test_configs_exist():
    assert {
        "ablation_activation",
        "ablation_batchnorm",
        "ablation_regularization",
        "ablation_shape",
        "ablation_scheduler",
        "ablation_increments",
        "ablation_augmentation",
        "ablation_train_duration",
    } <= set(EXPERIMENTS)
    assert "euroc_optuna" in SEARCHES
    assert {"local", "slurm"} <= set(LAUNCHERS)


@pytest.mark.parametrize("name", EXPERIMENTS)
def test_experiment_composes(name):
    """Every experiment config composes into a model, loss and data module; an ablation also at every
    point of its sweep, with the 4 paired seeds whose held-out flight is the seed (cv_fold = seed)."""
    cfg = compose_train([f"experiment={name}"])
    _build(cfg)
    params = cfg.hydra.sweeper.get("params")
    params = OmegaConf.to_container(params) if params is not None else {}
    if name.startswith("ablation_"):
        assert params["seed"] == "0,2,3,5", "every ablation runs the 4 paired seeds per setting"
        assert cfg.dataset.cv_fold == cfg.seed, "the held-out validation flight is tied to the seed"
        assert cfg.task_name == name
        assert cfg.dataset.name == "euroc", "the paper's claims are about EuRoC, not the sim default"
    for key, values in params.items():
        if key == "seed":
            continue
        for value in _split_sweep(str(values)):
            point = compose_train([f"experiment={name}", f"{key}={value}"])
            window, block = point.dataset.window, max(point.loss.increments)
            assert window % block == 0, f"{name}: window {window} is not a multiple of j={block}"
            _build(point)


def _split_sweep(values: str) -> list[str]:
    """'a,b' -> [a, b]; '[4,8],[8,16]' -> ['[4,8]', '[8,16]'] (commas inside brackets kept)."""
    out, depth, cur = [], 0, ""
    for ch in values:
        depth += ch == "["
        depth -= ch == "]"
        if ch == "," and depth == 0:
            out.append(cur.strip())
            cur = ""
        else:
            cur += ch
    return [*out, cur.strip()]


def _build(cfg) -> None:
    from gyrodenoise.losses import IncrementLoss
    from gyrodenoise.models.build import build_model

    build_model(**OmegaConf.to_container(cfg.model, resolve=True))
    IncrementLoss(**OmegaConf.to_container(cfg.loss, resolve=True))
    if cfg.dataset._target_.endswith(".ImuDataModule"):  # constructs only: no data is read before setup()
        if cfg.dataset.get("cv_fold") == "all":  # every fold in turn (gyrodenoise.all_folds): each is one data module
            cfg = OmegaConf.merge(cfg, {"dataset": {"cv_fold": 0}})
        hydra.utils.instantiate(cfg.dataset)


@pytest.mark.parametrize("name", SEARCHES)
def test_hparams_search_composes(name):
    require_plugin("hydra_plugins.hydra_optuna_sweeper")
    cfg = compose_train([f"hparams_search={name}"])
    assert cfg.hydra.sweeper._target_.endswith("OptunaSweeper")
    assert cfg.dataset.name == name.split("_")[0]
    assert cfg.hydra.sweeper.direction == "minimize"
    assert cfg.hydra.sweeper.params


@pytest.mark.parametrize("name", LAUNCHERS)
def test_launcher_composes(name):
    plugin = {"local": "hydra_joblib_launcher", "slurm": "hydra_submitit_launcher"}[name]
    require_plugin(f"hydra_plugins.{plugin}")
    cfg = compose_train(["experiment=ablation_activation", f"hydra/launcher={name}"])
    assert cfg.hydra.launcher._target_.startswith("hydra_plugins.")


def test_default_dataset_is_simulated():
    """`python -m gyrodenoise.train` out of the box needs no download; a command-line dataset wins over
    an experiment's choice."""
    assert compose_train([]).dataset.name == "sim"
    assert compose_train(["experiment=sim_quick"]).dataset.name == "sim"
    assert compose_train(["experiment=ablation_activation", "dataset=tumvi"]).dataset.name == "tumvi"


def test_ema_callbacks_compose():
    """callbacks=ema keeps the default callbacks and adds Lightning's EMA weight averaging (with batch-norm
    statistics recomputed for the averaged weights)."""
    cb = compose_train(["callbacks=ema"]).callbacks
    assert {"model_checkpoint", "last_checkpoint", "ema"} <= set(cb)
    ema = hydra.utils.instantiate(cb.ema)
    assert isinstance(ema, EMAWeightAveraging) and ema.bn_batches == 20


def test_ddp_trainer_composes():
    cfg = compose_train(["trainer=ddp"])
    assert cfg.trainer.strategy == "ddp" and cfg.trainer.sync_batchnorm


# --- tiny synthetic ASL data ------------------------------------------------------------------------


@pytest.fixture(scope="module")
def tiny_root(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("asl")
    for i, name in enumerate(["seq_a", "seq_b", "seq_c"]):
        write_asl_sequence(root / name, seconds=8.0, seed=i)
    return root


def tiny_overrides(root: Path) -> list[str]:
    return [
        f"dataset.root={root}",
        "dataset.train_seqs=[seq_a,seq_b]",
        "dataset.test_seqs=[seq_c]",
        "dataset.train_duration_s=5",
        "dataset.window=256",
        "dataset.gt_files={}",
        "dataset.eval_gt_variants={}",
        "model.channels=[4,8]",
        "model.dilations=[1,2]",
        "trainer.max_epochs=2",
        "trainer.check_val_every_n_epoch=1",
        "trainer.accelerator=cpu",
        "optim.scheduler.T_0=1",
    ]


def test_two_point_multirun_end_to_end(tiny_root, tmp_path):
    """`-m experiment=ablation_activation` restricted to 2 settings x 1 seed, then collected."""
    sweep_dir = tmp_path / "multirun"
    proc = run_train(
        [
            "-m",
            "experiment=ablation_activation",
            "model.act=gelu,relu",
            "seed=0",
            *tiny_overrides(tiny_root),
            f"hydra.sweep.dir={sweep_dir}",
        ],
        cwd=tmp_path,
    )
    log = proc.stdout + proc.stderr
    assert "#0 : " in log and "#1 : " in log  # Hydra's launch lines: two jobs
    for box in "━╭╰│":  # Rich's progress bar / tables: the log stays plain text
        assert box not in log, f"rich output in the log ({box!r})"

    runs, unfinished = ablation.find_runs([sweep_dir])
    assert len(runs) == 2 and not unfinished
    for r in runs:
        assert np.isfinite(r.metric("val")) and np.isfinite(r.metric("test"))
        assert (r.path / "tensorboard").is_dir()  # hparams view next to final val/test AOE
    assert ablation.ablated_keys(runs) == ["model.act"]

    out = tmp_path / "report" / "act"
    assert ablation.main([str(sweep_dir), "--out", str(out)]) == 0
    md = (out.parent / "act.md").read_text()
    assert "| model.act | seeds |" in md and "| gelu | 1 |" in md and "| relu | 1 |" in md
    rows = list(csv.DictReader(open(out.parent / "act.csv")))
    assert [r["model.act"] for r in rows] == ["gelu", "relu"]
    assert (out.parent / "act.png").read_bytes()[:4] == b"\x89PNG"
    # hparams of every run logged with the final metrics in TensorBoard
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    ev = EventAccumulator(str(runs[0].path / "tensorboard"))
    ev.Reload()
    assert "_hparams_/session_start_info" in ev.summary_metadata


def test_collect_filters_and_errors(tmp_path):
    def fake_run(d: Path, overrides: list[str], cfg: str, val: float, test: float) -> None:
        (d / ".hydra").mkdir(parents=True)
        (d / ".hydra" / "overrides.yaml").write_text("".join(f"- {o}\n" for o in overrides))
        (d / ".hydra" / "config.yaml").write_text(cfg)
        (d / "summary.json").write_text(
            f'{{"val": {{"val/aoe_deg": {val}}}, "test": {{"test/aoe_deg": {test}}}, "train_wall_time_s": 1}}'
        )

    cfg = "model:\n  act: {act}\n  batch_norm: {bn}\nseed: {seed}\n"
    for i, (act, bn) in enumerate([("gelu", "true"), ("relu", "true"), ("gelu", "false")]):
        for seed in range(3):
            overrides = (
                [f"model.act={act}", f"seed={seed}"] if bn == "true" else [f"model.batch_norm={bn}", f"seed={seed}"]
            )
            fake_run(
                tmp_path / "m" / f"{i}_{seed}",
                overrides,
                cfg.format(act=act, bn=bn, seed=seed),
                1.0 + i + 0.1 * seed,
                2.0 + i,
            )
    (tmp_path / "m" / "crashed" / ".hydra").mkdir(parents=True)
    (tmp_path / "m" / "crashed" / ".hydra" / "overrides.yaml").write_text("- seed=9\n")

    settings = ablation.collect(
        [tmp_path / "m"], tmp_path / "bn", keys=["model.batch_norm"], where=[("model.act", "gelu")]
    )
    assert [s.values for s in settings] == [("true",), ("false",)]
    mean, sd, n = settings[0].stats("val")
    assert n == 3 and mean == pytest.approx(1.1) and sd == pytest.approx(0.1)
    assert "Unfinished runs left out (no summary.json): " in (tmp_path / "bn.md").read_text()
    assert "/m/crashed" in (tmp_path / "bn.md").read_text()  # named, not only counted
    assert "repeated" not in (tmp_path / "bn.md").read_text()
    # without the filter, batch_norm=true holds gelu and relu runs of the same seeds: said, not averaged silently
    ablation.collect([tmp_path / "m"], tmp_path / "bn_all", keys=["model.batch_norm"])
    assert "model.batch_norm=true: 6 runs but seed(s) 0, 1, 2 repeated" in (tmp_path / "bn_all.md").read_text()

    assert ablation.main([str(tmp_path / "nope"), "--out", str(tmp_path / "x")]) == 2
    assert ablation.main([str(tmp_path / "m"), "--out", str(tmp_path / "x"), "--where", "model.act=tanh"]) == 2


def test_optuna_search_end_to_end(tiny_root, tmp_path):
    """`hparams_search=euroc_optuna` (no -m needed) minimises the returned val/aoe_deg; the study kept in a database
    as the config says (optuna 2.10 with SQLAlchemy 2 failed there: a bare AssertionError; the sweep extra pins 1.4)."""
    require_plugin("hydra_plugins.hydra_optuna_sweeper")
    sweep_dir = tmp_path / "optuna"
    run_train(
        [
            "hparams_search=euroc_optuna",
            "hydra.sweeper.n_trials=2",
            "hydra.sweeper.sampler.n_startup_trials=1",
            f"hydra.sweeper.storage=sqlite:///{tmp_path / 'optuna.db'}",
            *tiny_overrides(tiny_root),
            "dataset.name=mine",  # own data: the study is named after it, not 'euroc_denoiser' (audit 63)
            "logger=none",
            f"hydra.sweep.dir={sweep_dir}",
        ],
        cwd=tmp_path,
    )
    assert (tmp_path / "optuna.db").stat().st_size > 0
    import optuna

    studies = optuna.get_all_study_summaries(f"sqlite:///{tmp_path / 'optuna.db'}")
    assert [st.study_name for st in studies] == ["mine_denoiser"]
    import yaml

    result = yaml.safe_load((sweep_dir / "optimization_results.yaml").read_text())
    runs, _ = ablation.find_runs([sweep_dir])
    assert len(runs) == 2
    assert result["best_value"] == pytest.approx(min(r.metric("val") for r in runs), rel=1e-5)
    assert set(result["best_params"]) == {
        "optim.lr",
        "optim.weight_decay",
        "model.dropout",
        "model.act",
        "loss.huber_delta",
    }
