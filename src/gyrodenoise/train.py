"""Hydra entry point: train a correction model, keep its final weights (or, with `select=best_val`, the best
checkpoint on validation), test it.

    python -m gyrodenoise.train dataset=euroc model.act=gelu
    python -m gyrodenoise.train dataset=euroc model=calibrated
    python -m gyrodenoise.train ckpt_path=outputs/.../checkpoints/last.ckpt   # resume

Lightning is imported by the functions that train, not by this module: a command refused for its config ends in
a few seconds instead of after Lightning's import (~8 s on 2 cores).

Outputs (in the run folder): checkpoints/, tensorboard/, csv/, model.pt (the kept weights in the
shipped-model format), calibrated.pt (the baseline fitted on the same data) and summary.json (wall time,
validation and test metrics of the kept weights).
"""

from __future__ import annotations

# ruff: noqa: E402
# (the imports follow the hand-over below)
if __name__ == "__main__":  # python -m gyrodenoise.train: a Ctrl-C during the imports below ends in one line
    from gyrodenoise.launch import run_as_main

    run_as_main("train")  # imports this module as gyrodenoise.train (as the console script does), runs main

import inspect
import math
import os
import shlex
import signal
import sys
import time
import warnings
import zipfile
from pathlib import Path
from typing import TYPE_CHECKING

import hydra
import torch
from hydra.core.hydra_config import HydraConfig
from hydra.types import RunMode
from omegaconf import DictConfig, ListConfig, OmegaConf, open_dict

from gyrodenoise import all_folds
from gyrodenoise.atomic import write_json
from gyrodenoise.baseline import evaluate_on, fit_calibrated, safety_meta
from gyrodenoise.cli_errors import ConfigError, TrainingDiverged, hydra_key_hints, torch_threads, user_errors
from gyrodenoise.config import with_output_dir
from gyrodenoise.cpu_memory import retain_freed_memory
from gyrodenoise.job_log import console_to_job_log
from gyrodenoise.losses import IncrementLoss
from gyrodenoise.metrics import AOE_DEFINITION
from gyrodenoise.models.build import causality_leak
from gyrodenoise.notices import device_lines_said, lightning_lines_once, quiet_library_notices
from gyrodenoise.paths import portable_path, portable_tree, recorded_command
from gyrodenoise.pretrained import save_model
from gyrodenoise.provenance import code_version as _code_version
from gyrodenoise.provenance import library_versions, machine_description
from gyrodenoise.run_record import restored_on_refusal
from gyrodenoise.tables import markdown_table

if TYPE_CHECKING:
    import lightning.pytorch as L

    from gyrodenoise.data.datamodule import ImuDataModule
    from gyrodenoise.lit import DenoiserModule


def flat_hparams(cfg: DictConfig) -> dict:
    """Scalar hyperparameters for the loggers' view of a sweep (TensorBoard's hparams, MLflow's params)."""
    out = {}
    for group in ("model", "optim", "loss"):
        node = OmegaConf.to_container(cfg[group], resolve=True)
        stack = [(group, node)]
        while stack:
            prefix, n = stack.pop()
            for k, v in n.items():
                key = f"{prefix}.{k}"
                if isinstance(v, dict):
                    stack.append((key, v))
                else:
                    out[key] = v if isinstance(v, int | float | str | bool) else str(v)
    out["dataset"] = cfg.dataset.name
    out["seed"] = cfg.seed
    # what the data-side ablations sweep (amount of data, crops, augmentation) and the schedule length
    for key in ("train_duration_s", "window", "crops_per_epoch"):
        if cfg.dataset.get(key) is not None:
            out[f"dataset.{key}"] = cfg.dataset[key]
    for k, v in (cfg.dataset.get("augment") or {}).items():
        if isinstance(v, int | float | str | bool):
            out[f"dataset.augment.{k}"] = v
    out["trainer.max_epochs"] = cfg.trainer.get("max_epochs")
    return out


def format_test_table(test: dict[str, float], calibrated: dict[str, float] | None = None) -> str:
    """Per-sequence test AOE of the trained model next to the raw IMU and, when given ({sequence: AOE}),
    the calibrated baseline fitted on the same data, as a markdown table."""
    names = sorted(k.split("/", 2)[2] for k in test if k.startswith("test/aoe_deg/"))
    header = ["sequence", "model AOE 3D/yaw (deg)", "raw IMU AOE 3D (deg)"]
    if calibrated:
        header.append("calibrated AOE 3D (deg)")
    rows = []
    for n in [*names, None]:
        suffix = f"/{n}" if n else ""
        cells = [test.get(f"test/{k}{suffix}", math.nan) for k in ("aoe_deg", "aoe_yaw_deg", "raw_imu_aoe_deg")]
        rows.append([n or "**average**", f"{cells[0]:.2f}/{cells[1]:.2f}", f"{cells[2]:.2f}"])
        if calibrated:
            cal = calibrated.get(n, math.nan) if n else sum(calibrated.values()) / len(calibrated)
            rows[-1].append(f"{cal:.2f}")
    return markdown_table(header, rows)


CAUSAL_TOL = 1e-3  # of the model's sensitivity to its past; float32 rounding of a causal model stays far below


def wants_calibrated_baseline(cfg: DictConfig) -> bool:
    """Whether the run fits the calibrated baseline beside its model (not when the model is that baseline)."""
    return bool(cfg.get("calibrated_baseline")) and cfg.model.name != "calibrated"


def calibrated_baseline(cfg: DictConfig, dm: ImuDataModule, module: DenoiserModule, out_dir: Path) -> dict:
    """The safety net: the 12-parameter calibrated baseline fitted on the same training data with the
    same loss (seconds), scored on the same validation ("val" group: the held-out flight under
    cross-validation) and test sequences; whether the trained model beats it on validation."""
    start = time.time()
    cal = fit_calibrated(dm.train_part, loss=OmegaConf.to_container(cfg.loss, resolve=True))
    cal_path = out_dir / "calibrated.pt"
    # the run's data facts, as fit_calibrated records them: evaluate's training-overlap warning, correct's sensor
    # and rate checks read them
    save_model(cal, {"name": "calibrated"}, cal_path, meta={**dm.model_meta(), "fit": "baseline.fit_calibrated"})
    val_seqs = [seq for seq, group in zip(dm.val_part, dm.val_groups, strict=True) if group == "val"]
    out = safety_meta(module.model, cal, val_seqs, calibrated_path=cal_path.name)
    if cfg.get("test") and dm.test_part:
        per_seq = evaluate_on(cal, dm.test_part)
        out["calibrated_test_aoe_deg"] = float(sum(per_seq.values()) / len(per_seq))
        out["calibrated_test_aoe_deg_per_sequence"] = per_seq
    out["fit_and_score_s"] = time.time() - start
    verdict = {
        True: "the model beats it on validation",
        False: "the model does NOT beat it on validation: prefer the calibrated model",
        None: "no validation data to compare them on",
    }[out["beats_calibrated"]]
    if out.get("calibrated_val_aoe_deg") is not None and out.get("model_val_aoe_deg_whole") is not None:
        verdict += (
            f" (AOE on the whole validation parts, model {out['model_val_aoe_deg_whole']:.2f} vs calibrated "
            f"{out['calibrated_val_aoe_deg']:.2f} deg; the validation AOE below is on the parts cut for the loss)"
        )
    print(f"calibrated baseline (same data, same loss, {cal_path.name}): {verdict}")
    return out


def _raw_final_weights(trainer: L.Trainer, module: DenoiserModule) -> DenoiserModule | None:
    """With a weight-averaging callback (callbacks=ema), `module` ends fit with the averaged weights; the
    final optimiser weights are in the last checkpoint's `current_model_state` (Lightning keeps them
    there). None without averaging, or (said in a warning) without a last checkpoint of the final epoch."""
    from lightning.pytorch.callbacks import ModelCheckpoint, WeightAveraging

    from gyrodenoise.lit import DenoiserModule

    if not any(isinstance(c, WeightAveraging) for c in trainer.callbacks):
        return None
    # ModelCheckpoint only: trainer.checkpoint_callbacks also lists the InterruptionCheckpoint (no monitor, no paths)
    plain = [c for c in trainer.checkpoint_callbacks if isinstance(c, ModelCheckpoint) and not c.monitor]
    last = next((c.last_model_path or c.best_model_path for c in plain), "")
    ckpt = torch.load(last, map_location="cpu", weights_only=True) if last else {}
    if "current_model_state" not in ckpt or ckpt.get("epoch") != trainer.current_epoch - 1:
        print(  # asked for with test_other_rule=true: say why it is missing from summary.json
            "warning: test_other_rule: the final weights without averaging are not scored: no last checkpoint of the "
            f"final epoch ({trainer.current_epoch}) holds them (make trainer.max_epochs a multiple of "
            "callbacks.last_checkpoint.every_n_epochs)"
        )
        return None
    raw = DenoiserModule(**module.hparams)
    raw.load_state_dict(ckpt["current_model_state"])
    return raw


def schedule_cut_note(cfg: DictConfig) -> str | None:
    """What to say when the run ends inside a cosine cycle (a short `trainer.max_epochs` with the default T_0): the
    rate never anneals, and the final weights are those of a high rate."""
    sched, epochs = cfg.optim.get("scheduler") or {}, cfg.trainer.get("max_epochs")
    if sched.get("name") != "cosine_warm_restarts" or not epochs or epochs < 0:
        return None
    start, length = 0, int(sched["T_0"])
    while start + length < epochs:  # the cycle the last epoch falls in
        start, length = start + length, length * int(sched.get("T_mult", 1))
    if start + length == epochs:
        return None
    lr, eta_min = float(cfg.optim.lr), float(sched.get("eta_min", 0.0))
    end = eta_min + (lr - eta_min) * (1 + math.cos(math.pi * (epochs - start) / length)) / 2
    return (
        f"trainer.max_epochs={epochs} ends {epochs - start} epochs into a {length}-epoch cosine cycle "
        f"(optim.scheduler.T_0={sched['T_0']}, T_mult={sched.get('T_mult', 1)}): the learning rate ends at {end:.3g}, "
        f"not annealed to eta_min={eta_min:g}. For a shorter run give the cycle its length too, e.g. "
        f"optim.scheduler.T_0={epochs}"
    )


NUMBERS = (  # (key, whole number?, an example) of the settings a run reads as numbers
    ("seed", True, "0"),
    ("optim.lr", False, "0.01"),
    ("optim.weight_decay", False, "0.1"),
    ("model.dropout", False, "0.1"),
    ("loss.huber_delta", False, "0.005"),
    ("loss.weight", False, "1e6"),
    ("trainer.max_epochs", True, "600"),
)


def check_loss(cfg: DictConfig) -> None:
    """The `loss` node builds the loss (a ConfigError naming the setting): a key it does not take was a TypeError, a
    scalar or a zero increment a TypeError or a ZeroDivisionError below, a huber_delta <= 0 torch's error at the
    first training step."""
    loss = OmegaConf.to_container(cfg.get("loss") or OmegaConf.create({}), resolve=True)
    takes = list(inspect.signature(IncrementLoss).parameters)
    if unknown := sorted(set(loss) - set(takes)):
        raise ConfigError(f"loss.{unknown[0]} is not a setting of the loss; it takes {', '.join(takes)}")
    try:
        IncrementLoss(**loss)
    except ValueError as e:
        raise ConfigError(str(e)) from None


def check_choices(cfg: DictConfig) -> None:
    """The choices that need neither data nor a model (`select`, the loss increments against the crop length): a bad
    one ends the command at once, before any data is read."""
    if cfg.select not in ("last", "best_val"):
        raise ConfigError(f"select={cfg.select!r}: choose 'last' (final weights) or 'best_val'")
    for key, whole, example in NUMBERS:  # 'optim.lr=abc' ended in a comparison's TypeError deep in the optimiser
        value = OmegaConf.select(cfg, key, default=None)
        if value is not None and (isinstance(value, bool) or not isinstance(value, int if whole else (int, float))):
            kind = "a whole number" if whole else "a number"
            raise ConfigError(f"{key}={value!r}: give {kind}, e.g. {key}={example}")
    check_loss(cfg)
    data_inc, loss_inc = cfg.dataset.get("increments"), cfg.get("loss", {}).get("increments")
    if data_inc is not None and loss_inc is not None:
        data_list = list(data_inc) if isinstance(data_inc, ListConfig) else data_inc  # a scalar is no list
        if data_list != list(loss_inc):
            raise ConfigError(
                f"dataset.increments={data_list} differs from loss.increments={list(loss_inc)}: set loss.increments "
                "(the dataset follows it)"
            )
    window, block = cfg.dataset.get("window"), max(loss_inc or data_inc or [1])
    if window is not None and (isinstance(window, bool) or not isinstance(window, int) or window < block):
        raise ConfigError(  # a negative window passed the test below and stopped at the crops as 'too short' data
            f"dataset.window={window!r}: the samples per training crop, a whole multiple of the longest loss increment "
            f"({block} samples) and at least that, e.g. dataset.window=9600 (48 s at 200 Hz)"
        )
    if window is not None and window % block:
        raise ConfigError(
            f"dataset.window={window} is not a multiple of the longest loss increment ({block} samples): give e.g. "
            f"dataset.window={window - window % block} or {window - window % block + block}"
        )


def build_module(cfg: DictConfig) -> DenoiserModule:
    """The module of the run, its optimiser and schedule built once to check the config: a bad choice
    (`select`, `optim.scheduler.name`, `model.act`, ...) ends the command before the fit, in one line."""
    from gyrodenoise.lit import DenoiserModule

    check_choices(cfg)
    window = cfg.dataset.get("window")
    try:
        module = DenoiserModule.from_config(cfg)
        module.configure_optimizers()
    except ValueError as e:
        raise ConfigError(str(e)) from None
    if note := schedule_cut_note(cfg):
        print(f"warning: {note}")
    rf = int(getattr(module.model, "receptive_field", 1))
    if window is not None and window < rf:
        print(
            f"warning: dataset.window={window} samples is shorter than the model's receptive field ({rf} samples): "
            "every training output sees the padded start of its crop; give a window of several receptive fields"
        )
    return module


def _score_without_callbacks(cfg: DictConfig, dm, module: DenoiserModule, validate: bool = True) -> tuple[dict, dict]:
    """Validation (with `validate`) and, with cfg.test, test metrics of `module` by a trainer without callbacks or
    loggers. The run's own trainer would let a weight-averaging callback (callbacks=ema) swap its averaged
    weights in over the module scored, and would log this scoring as one more point of the validation curve."""
    # default_root_dir: a folder that does not exist. Under SLURM, Lightning restores a trainer whose ckpt_path is
    # None from <default_root_dir>/hpc_ckpt_*.ckpt (written by its SIGUSR1 auto-requeue): validate/test would
    # load that checkpoint's weights into `module` instead of scoring the weights given
    with device_lines_said():
        plain: L.Trainer = hydra.utils.instantiate(
            cfg.trainer,
            callbacks=[],
            logger=False,
            enable_checkpointing=False,
            enable_progress_bar=False,
            enable_model_summary=False,  # the run's trainer printed it
            default_root_dir=str(Path(cfg.paths.output_dir) / ".scoring-no-hpc-resume"),
        )
    val = (plain.validate(module, datamodule=dm, verbose=False) or [{}])[0] if validate else {}  # {}: no val data
    test = plain.test(module, datamodule=dm, verbose=False)[0] if cfg.get("test") else {}
    return val, test


def _last_ckpt_cadence(cfg: DictConfig) -> str:
    """How often this run's config writes checkpoints/last.ckpt, for the messages that point to it."""
    n = OmegaConf.select(cfg, "callbacks.last_checkpoint.every_n_epochs", default=None)
    return f"written every {n} epochs" if n else "written only if callbacks.last_checkpoint is configured"


def _say_how_to_resume(trainer: L.Trainer, cfg: DictConfig) -> None:
    ckpts = Path(cfg.paths.output_dir) / "checkpoints"
    saved = [p for p in (ckpts / "interrupted.ckpt", ckpts / "last.ckpt") if p.is_file()]
    if not saved and trainer.global_step == 0 and not cfg.get("ckpt_path"):
        print(
            "interrupted before the first training step: nothing was trained or saved, so nothing to resume; rerun "
            "the command to start again",
            file=sys.stderr,
        )
        return
    where = f"ckpt_path={saved[0]}" if saved else "ckpt_path=<a run's checkpoints/last.ckpt>"
    print(
        f"interrupted at epoch {trainer.current_epoch}: no model.pt written; resume with {where}"
        + (" (written at the end of that epoch)" if saved and saved[0].name == "interrupted.ckpt" else "")
        + f", or {_rerun_in_folder(cfg)}: a run folder holding an unfinished "
        f"run resumes from its newest checkpoint (auto_resume; last.ckpt is {_last_ckpt_cadence(cfg)})",
        file=sys.stderr,
    )


def _rerun_in_folder(cfg: DictConfig) -> str:
    """How to rerun this run in its own folder. A sweep's job is rerun alone, with its own values: the sweep's command
    with -m would run every job again, and hydra.run.dir does not apply to it."""
    folder = f"hydra.run.dir={cfg.paths.output_dir}"
    if HydraConfig.initialized() and HydraConfig.get().mode == RunMode.MULTIRUN:
        job = shlex.join([*HydraConfig.get().overrides.task, folder])
        return f"rerun this job of the sweep alone: python -m gyrodenoise.train {job}"
    return f"rerun the same command with {folder}"


_LOADED_CODE: dict | None = None  # the code this process loaded, read once: a later commit or edit is not this run's


def loaded_code_version() -> dict:
    """`_code_version()` at the first training of this process (the CLI's only one): a run that takes minutes records
    the commit it started from, not whatever the checkout holds when it ends (edits during a run marked it dirty, a
    commit during a run gave the later commit)."""
    global _LOADED_CODE
    if _LOADED_CODE is None:
        _LOADED_CODE = _code_version()
    return _LOADED_CODE


def train(cfg: DictConfig) -> dict:
    """Fit, select, score and save one run of a composed train config (`gyrodenoise.config.compose_config("train",
    [...])`; from Python it needs `paths.output_dir=...`). Returns the summary written to `output_dir/summary.json`
    (its `output_dir` holds `model.pt`). Called from Python it leaves torch's thread count as it found it and does
    not apply `retain_freed_memory` (the caller's process would keep its peak memory until it exits)."""
    out_dir = with_output_dir(cfg, "paths.output_dir")  # before any global setting changes
    check_choices(cfg)
    loaded_code_version()  # now, before the fit
    if cfg.get("retain_freed_memory", True) and HydraConfig.initialized():
        retain_freed_memory()
    with torch_threads(cfg.get("threads")):
        if all_folds.wants_all_folds(cfg):  # every fold in turn: the protocol's figure as val/aoe_deg
            return all_folds.train_all_folds(cfg, out_dir, _train)
        if (out_dir / "model.pt").is_file():  # a second run there would leave a mix of both runs' files
            raise ConfigError(
                f"{out_dir} holds a finished run (model.pt): a new run there would mix its outputs with that run's "
                "(checkpoints, logs, curves). Give another folder (hydra.run.dir=...), or remove that one first."
            )
        return _train(cfg, out_dir)


RUNTIME_ONLY = ("figure_every_n_val", "optim.cuda_graph")  # settings that do not change what a run learns


def _flat(tree: object, prefix: str = "") -> dict[str, object]:
    if isinstance(tree, dict):
        return {k: v for key, sub in tree.items() for k, v in _flat(sub, f"{prefix}{key}.").items()}
    return {prefix[:-1]: list(tree) if isinstance(tree, tuple) else tree}


# data settings that change nothing of what a run learns (where the files are, what is scored after the fit)
DATA_RUNTIME_ONLY = ("root", "cache_dir", "test_seqs", "eval_gt_variants", "inconsistent_truth")


def resume_settings(cfg: DictConfig) -> dict:
    """The seed and the data settings a checkpoint records beside the module's hyperparameters
    (`check_resumed_settings`): a resume with another seed or other data would record them in summary.json and go on
    with the checkpoint's random stream, and mix two data settings in one run."""
    data = {k: v for k, v in OmegaConf.to_container(cfg.dataset, resolve=True).items() if k not in DATA_RUNTIME_ONLY}
    return {"seed": cfg.get("seed"), "dataset": portable_tree(data)}


def check_resumed_settings(ckpt_path: str, hparams: dict, settings: dict | None = None) -> int:
    """ConfigError when the command's model, optimiser, schedule or loss, or (`settings`, checkpoints written since
    they record them) its seed and data settings, differ from those the checkpoint was trained with: the resumed fit
    goes on with the checkpoint's weights, optimiser, schedule and random stream, so the new values would be recorded
    in summary.json but not used (a changed network ends in a size-mismatch traceback). Returns the checkpoint's
    epochs done."""
    ckpt = torch.load(ckpt_path, map_location="cpu", weights_only=False)
    was = _flat(OmegaConf.to_container(OmegaConf.create(dict(ckpt.get("hyper_parameters") or {})), resolve=True))
    now = _flat(OmegaConf.to_container(OmegaConf.create(hparams), resolve=True))
    if settings is not None and ckpt.get("run_settings") is not None:
        if settings.get("seed") is None:  # seed=null resumed: the run goes on with the seed its first part drew
            settings["seed"] = ckpt["run_settings"].get("seed")
        was |= _flat(ckpt["run_settings"])
        now |= _flat(settings)
    keys = [k for k in sorted(set(was) | set(now)) if k not in RUNTIME_ONLY and was.get(k) != now.get(k)]
    # a key the checkpoint lacks is a setting a later version added (null keys are equal already): refusing it would
    # refuse every resume across an upgrade, so it is said, not refused
    if added := [k for k in keys if k not in was]:
        warnings.warn(
            f"resuming from {ckpt_path}, written by a version without "
            + ", ".join(f"{k} (here {now[k]!r})" for k in added)
            + ": the resumed epochs use these values; if they change what the run learns, start afresh",
            UserWarning,
            stacklevel=2,
        )
    if differ := [k for k in keys if k in was]:
        listed = "; ".join(f"{k}={was[k]!r} there, {now.get(k)!r} here" for k in differ[:6])
        raise ConfigError(
            f"resuming from {ckpt_path}, whose run was trained with other settings ({listed}): a resumed run goes on "
            "with the checkpoint's weights, optimiser and schedule, so these would be recorded but not used. Give the "
            "run's settings to resume it, or start afresh (auto_resume=false, or another hydra.run.dir)."
        )
    return int(ckpt.get("epoch", -1)) + 1  # written at an epoch's end: Lightning's 0-based epoch of that end


def _keep_earlier_csv_curves(loggers: list) -> None:
    """Lightning's CSVLogger deletes the metrics.csv it finds in its folder; a run resumed in its own folder keeps the
    curves up to the interruption under another name (TensorBoard and MLflow keep theirs by themselves)."""
    from lightning.pytorch.loggers import CSVLogger

    for lg in loggers:
        metrics = Path(lg.log_dir) / "metrics.csv" if isinstance(lg, CSVLogger) else None
        if metrics is not None and metrics.is_file():
            kept = metrics.with_name(f"metrics_before_resume_{time.strftime('%Y%m%d-%H%M%S')}.csv")
            metrics.rename(kept)
            print(f"note: the curves before the resume are kept in {kept} (this run's {metrics.name} goes on from it)")


def _resume_point(out_dir: Path) -> Path | None:
    """The newest readable checkpoint of an unfinished run in `out_dir` (no model.pt): checkpoints/last.ckpt (every
    50 epochs), checkpoints/interrupted.ckpt (written when the run was stopped) or a checkpoint of Lightning's SLURM
    auto-requeue (hpc_ckpt_N.ckpt)."""
    if (out_dir / "model.pt").is_file():
        return None
    ckpts = out_dir / "checkpoints"
    found = [ckpts / "last.ckpt", ckpts / "interrupted.ckpt", *out_dir.glob("hpc_ckpt_*.ckpt")]
    found = [p for p in found if p.is_file() and zipfile.is_zipfile(p)]
    return max(found, key=lambda p: p.stat().st_mtime, default=None)


def _train(cfg: DictConfig, out_dir: Path) -> dict:
    import lightning.pytorch as L
    from lightning.pytorch.callbacks import LearningRateMonitor, ModelCheckpoint, ProgressBar
    from lightning.pytorch.utilities.exceptions import SIGTERMException

    from gyrodenoise.data.datamodule import TAIL_NAME_NOTE
    from gyrodenoise.interruption_checkpoint import stopped_by
    from gyrodenoise.lit import DenoiserModule
    from gyrodenoise.run_loggers import log_run_end

    lightning_lines_once()
    if cfg.get("ckpt_path") is None and cfg.get("auto_resume") and (resume := _resume_point(out_dir)):
        # a requeued job (SLURM time limit, preemption: the launcher reruns it in the same folder) goes on from its
        # own checkpoint instead of starting again; a finished run (model.pt) is not resumed
        print(f"auto_resume: this run folder holds an unfinished run's {resume}: resuming from it (auto_resume=false "
              "starts afresh)")  # fmt: skip
        with open_dict(cfg):
            cfg.ckpt_path = str(resume)
    if cfg.get("ckpt_path") and not zipfile.is_zipfile(cfg.ckpt_path):  # before any data is read
        what = (
            "not a readable Lightning checkpoint (truncated or damaged)"
            if Path(cfg.ckpt_path).is_file()
            else ("no such file")
        )
        raise ConfigError(
            f"ckpt_path={cfg.ckpt_path}: {what}; give "
            f"a run's checkpoints/last.ckpt ({_last_ckpt_cadence(cfg)}), or leave ckpt_path out to start afresh"
        )
    if cfg.get("seed") is None and not cfg.get("ckpt_path"):  # drawn, and recorded, so that the run can be rerun
        with open_dict(cfg):
            cfg.seed = int.from_bytes(os.urandom(4), "little") >> 1
        print(f"note: seed=null: drew seed={cfg.seed} (recorded in summary.json; seed={cfg.seed} reruns this run)")
    if cfg.get("seed") is not None:
        L.seed_everything(cfg.seed, workers=True)
    out_dir.mkdir(parents=True, exist_ok=True)
    dm = hydra.utils.instantiate(cfg.dataset)
    dm.check_sequences(test=bool(cfg.get("test")))
    if cfg.get("test") and (both := [n for n in dm.test_names if n in dm.train_names]):
        print(
            f"warning: test sequence(s) {', '.join(both)} are also training sequences: "
            "their test figures are not held out"
        )
    module = build_module(cfg)
    module.run_settings = resume_settings(cfg)
    resumed_at = None
    if cfg.get("ckpt_path"):
        resumed_at = check_resumed_settings(cfg.ckpt_path, dict(module.hparams), module.run_settings)
        with open_dict(cfg):
            cfg.seed = module.run_settings["seed"]
    loggers = [hydra.utils.instantiate(lg) for lg in (cfg.get("logger") or {}).values()]
    callbacks = [hydra.utils.instantiate(c) for c in (cfg.get("callbacks") or {}).values()]
    if not loggers:  # Lightning refuses a learning-rate monitor without a logger
        callbacks = [c for c in callbacks if not isinstance(c, LearningRateMonitor)]
    if cfg.trainer.get("enable_progress_bar") is False:  # Lightning refuses a progress-bar callback then
        callbacks = [c for c in callbacks if not isinstance(c, ProgressBar)]
    quiet_library_notices()
    trainer: L.Trainer = hydra.utils.instantiate(cfg.trainer, callbacks=callbacks, logger=loggers or False)

    # one optimiser step per epoch: log_every_n_steps counts steps across epochs, as intended here
    warnings.filterwarnings("ignore", message=r"The number of training batches \(\d+\) is smaller than the logging")
    if cfg.get("ckpt_path"):
        _keep_earlier_csv_curves(loggers)
        # Lightning warns that a checkpoint from another folder does not bring its best-score bookkeeping: true and
        # expected when resuming into a new run folder; said once, plainly
        warnings.filterwarnings("ignore", message=r"The dirpath has changed from")
        print(
            f"resuming from {cfg.ckpt_path}: weights, optimiser, schedule and random state restored; the "
            "best-validation checkpoint is tracked afresh in this run's folder (the earlier run's stays in its own)"
        )
    start = time.time()
    try:
        trainer.fit(module, datamodule=dm, ckpt_path=cfg.get("ckpt_path"))
    except SystemExit as e:  # a second Ctrl-C, or a SIGTERM without our callback: say what was kept, how to go on
        if trainer.interrupted:
            _say_how_to_resume(trainer, cfg)
        if isinstance(e, SIGTERMException):  # Lightning raises it with no code: the process would exit 0
            raise SystemExit(128 + signal.SIGTERM) from None
        if trainer.interrupted and e.code == 1:  # Lightning's exit after a KeyboardInterrupt: the shell's code for it
            raise SystemExit(128 + signal.SIGINT) from None
        raise
    except TrainingDiverged:  # its weights are NaN: nothing to resume from (auto_resume would pick it up)
        (out_dir / "checkpoints" / "interrupted.ckpt").unlink(missing_ok=True)
        raise
    if (signum := stopped_by(trainer)) is not None:  # stopped at an epoch's end, interrupted.ckpt written
        _say_how_to_resume(trainer, cfg)
        raise SystemExit(128 + signum)
    wall_s = time.time() - start
    step_kind = module.step_kind  # before `module` may become the best checkpoint's
    # with weight averaging (callbacks=ema) the run also scores its final weights without it (paired)
    raw_final = _raw_final_weights(trainer, module) if cfg.get("test_other_rule") else None

    # the model is chosen by a rule fixed before any test: the final weights (`select: last`, the end
    # of a cosine cycle) or the best validation checkpoint (`select: best_val`)
    # the monitored ModelCheckpoint (callbacks.model_checkpoint), not trainer.checkpoint_callback: without Lightning's
    # checkpoint callbacks that is the InterruptionCheckpoint, which has no monitor
    ckpt_cb = next((c for c in trainer.checkpoint_callbacks if isinstance(c, ModelCheckpoint) and c.monitor), None)
    best_path = ckpt_cb.best_model_path if ckpt_cb is not None else ""
    selected = f"final weights, epoch {trainer.current_epoch}"
    alternative = None  # the model the other rule would pick, tested too when cfg.test_other_rule
    if cfg.select == "best_val" and best_path:
        alternative, module = module, DenoiserModule.load_from_checkpoint(best_path, weights_only=True)
        selected = portable_path(best_path)
    elif cfg.select == "best_val" and ckpt_cb is None:
        selected += " (select=best_val, but no best-validation checkpoint callback: no best checkpoint)"
        print(
            "warning: select=best_val, but the run has no best-validation checkpoint callback "
            "(callbacks.model_checkpoint): the final weights are kept"
        )
    elif cfg.select == "best_val":
        selected += " (select=best_val, but no validation ran during the fit: no best checkpoint)"
        print(
            f"warning: select=best_val, but no validation ran during the {trainer.current_epoch} epochs "
            f"(trainer.check_val_every_n_epoch={trainer.check_val_every_n_epoch}): the final weights are kept"
        )
    elif cfg.select == "last" and best_path and cfg.get("test_other_rule"):
        alternative = DenoiserModule.load_from_checkpoint(best_path, weights_only=True)
    leak = causality_leak(module.model) if cfg.model.name == "custom" else None
    if leak is not None and not leak <= CAUSAL_TOL:  # NaN: the check could not tell
        print(
            f"warning: the model is not causal: its corrections move when only later samples change, by {leak:.2e} "
            "of how much later corrections move when earlier samples change (models.build.causality_leak; NaN: it "
            "outputs NaN). Its figures are optimistic and it cannot run onboard; check padding, centred "
            "convolutions, normalisations and poolings over time"
        )
    steps = ["validation", *(["test"] if cfg.get("test") else [])]
    baseline = wants_calibrated_baseline(cfg)
    print(f"scoring on {' and '.join(steps)}{', then the calibrated baseline' if baseline else ''} (seconds)")
    val, test = _score_without_callbacks(cfg, dm, module)
    test_other = {}
    if alternative is not None and cfg.get("test_other_rule") and cfg.get("test"):
        test_other = _score_without_callbacks(cfg, dm, alternative, validate=False)[1]
    val_raw_final, test_raw_final = _score_without_callbacks(cfg, dm, raw_final) if raw_final is not None else ({}, {})
    if (raw := val.get("val/raw_imu_aoe_deg")) is not None and val.get("val/aoe_deg", -math.inf) >= raw:
        print(
            f"warning: validation AOE {val['val/aoe_deg']:.2f} deg is not better than the raw gyro's {raw:.2f}: the "
            f"model corrects nothing (a learning rate too high, now optim.lr={cfg.optim.lr}? too few epochs?)"
        )
    for lg in trainer.loggers if test else []:  # the test figures beside the curves (not the post-fit validation)
        lg.log_metrics(test, step=trainer.global_step)
        lg.save()

    safety = calibrated_baseline(cfg, dm, module, out_dir) if baseline else {}
    reference = {
        f"baseline/calibrated_{k}": safety[f"calibrated_{k}"]
        for k in ("val_aoe_deg", "test_aoe_deg")
        if safety.get(f"calibrated_{k}") is not None
    }
    for lg in trainer.loggers if reference else []:  # the baseline beside the curves, at the run's last step
        lg.log_metrics(reference, step=trainer.global_step)
        lg.save()

    summary = {
        "command": recorded_command("train"),
        "output_dir": portable_path(out_dir),
        "overrides": list(HydraConfig.get().overrides.task) if HydraConfig.initialized() else [],
        "config": portable_tree(OmegaConf.to_container(cfg, resolve=True)),
        "seed": cfg.get("seed"),
        "dataset": cfg.dataset.name,
        "model": OmegaConf.to_container(cfg.model, resolve=True),
        "train_wall_time_s": wall_s,  # of this process's fit: a resumed run's, from the resume on
        "training_step": step_kind,
        "epochs": trainer.current_epoch,
        "machine": machine_description(),
        "versions": library_versions(),
        "torch_threads": torch.get_num_threads(),  # the figures reproduce to the digit at the same count
        "code_version": loaded_code_version(),
        "selection": cfg.select,
        "selected": selected,
        "best_checkpoint": portable_path(best_path) if best_path else "",
        "best_val_aoe_deg": float(ckpt_cb.best_model_score)
        if best_path and ckpt_cb.best_model_score is not None
        else None,
        "val": val,
        "test": test,
    }
    if resumed_at is not None:  # the checkpoint itself may be gone (interrupted.ckpt is removed at the end)
        summary["resumed_from"] = {"checkpoint": portable_path(cfg.ckpt_path), "epochs_done": resumed_at}
    if leak is not None:
        summary["causality_leak"] = leak
    if safety:
        summary["calibrated_baseline"] = safety
    if test_other:
        summary["test_other_rule"] = {"rule": "best_val" if cfg.select == "last" else "last", **test_other}
    if val_raw_final or test_raw_final:  # the final weights without the weight averaging
        summary["val_raw_final"], summary["test_raw_final"] = val_raw_final, test_raw_final
    save_model(
        module.model,
        OmegaConf.to_container(cfg.model, resolve=True),
        out_dir / "model.pt",
        meta={
            **dm.model_meta(),
            "val_aoe_deg": val.get("val/aoe_deg"),
            "test": test,
            "train_wall_time_s": wall_s,
            "machine": summary["machine"],
            "command": summary["command"],
            **({"causal": leak <= CAUSAL_TOL} if leak is not None else {}),
            **{k: safety[k] for k in ("beats_calibrated", "calibrated_val_aoe_deg", "calibrated_model") if k in safety},
        },
    )
    write_json(out_dir / "summary.json", summary)
    print(f"\nvalidation AOE {val.get('val/aoe_deg', math.nan):.3f} deg ({selected})")
    if test:
        table = format_test_table(test, safety.get("calibrated_test_aoe_deg_per_sequence"))
        print(f"test sequences ({cfg.dataset.name}, {cfg.model.name}):\n{table}", end="")
        print(
            f"(each cut to 1 + a multiple of {dm.block} samples, as the loss needs: the last digit can differ from "
            "`python -m gyrodenoise.evaluate`, which scores them whole)\n"
            f"{AOE_DEFINITION} Raw IMU: the gyro as recorded; calibrated: the 12-parameter baseline fitted on the "
            f"same training data. {TAIL_NAME_NOTE}"
        )
    print(f"outputs in {out_dir}")
    final = {k: v for k, v in {**val, **test}.items() if k.count("/") == 1}
    log_run_end(trainer.loggers, flat_hparams(cfg), final, out_dir)
    return summary


def single_run_of_a_sweep_note(cfg: DictConfig | None = None) -> str | None:
    """A note when the config defines a sweep (an experiment's hydra.sweeper.params) but runs without -m: one
    run of it is legitimate (the queues of benchmarks/run_queue.py run them so), but easy to do by mistake."""
    if not HydraConfig.initialized():
        return None
    hc = HydraConfig.get()
    params = dict((hc.sweeper.get("params") or {}) if "sweeper" in hc else {})
    if hc.mode != RunMode.RUN or not params:
        return None
    swept = ", ".join(f"{k} over {v}" for k, v in params.items())
    if cfg is not None and all_folds.wants_all_folds(cfg):  # experiment=cross_validation without -m
        return (
            f"note: this config defines a sweep ({swept}); without -m this run trains every fold in turn "
            "(dataset.cv_fold=all). With -m each fold is a job of its own (several at once with a parallel launcher)."
        )
    return f"note: this config defines a sweep ({swept}); this is one run of it. Add -m to run the sweep."


@hydra_key_hints("train")
@hydra.main(version_base="1.3", config_path="conf", config_name="train")
def main(cfg: DictConfig) -> float | None:
    with console_to_job_log(), user_errors(), restored_on_refusal():
        if note := single_run_of_a_sweep_note(cfg):
            print(note)
        summary = train(cfg)
    # the value an Optuna sweep minimises
    return summary["val"].get("val/aoe_deg")
