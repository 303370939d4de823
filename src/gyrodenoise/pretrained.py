"""Save and load trained correction models: shipped weights by name, or files.

A model file is a plain torch dict (loads with weights_only=True): the model's config values, its
state dict (normalisation statistics included) and metadata (dataset, split, metrics, command).
An ensemble is the same format: config {"name": "ensemble", "members": [member configs]}, state
dict keys `members.<k>.*`. Lightning checkpoints of DenoiserModule load too.

Safety metadata: `beats_calibrated` (True / False / None: unknown) says whether the model beat the
12-parameter calibrated baseline fitted on the same training data, on the validation data
(`calibrated_val_aoe_deg`); `not_better_warning` turns a False into the message users see.
"""

from __future__ import annotations

import inspect
import warnings
import zipfile
from importlib import resources
from pathlib import Path

import torch

from gyrodenoise.atomic import atomic_path
from gyrodenoise.data.checks import RATE_TOL
from gyrodenoise.models.build import build_model
from gyrodenoise.models.ensemble import CorrectionModel
from gyrodenoise.paths import portable_path
from gyrodenoise.provenance import file_sha256

FORMAT = "gyrodenoise-model/1"


def shipped_dir() -> Path:
    return Path(str(resources.files("gyrodenoise") / "weights"))


def available_models() -> list[str]:
    return sorted(p.stem for p in shipped_dir().glob("*.pt"))


def save_model(model: CorrectionModel, model_cfg: dict, path: str | Path, meta: dict | None = None) -> Path:
    """Write atomically: an interrupted save never leaves a file that looks whole."""
    path = Path(path)
    meta = dict(meta or {})
    if dict(model_cfg).get("name") == "custom" and (source := custom_source(model)):
        meta["custom_source"] = source
    payload = {
        "format": FORMAT,
        "model": dict(model_cfg),
        "state_dict": {k: v.detach().cpu() for k, v in model.state_dict().items()},
        "meta": meta,
    }
    # to a file object: the archive's entries are then named archive/..., not after the random temporary file
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        torch.save(payload, f)
    return path


def custom_source(model: torch.nn.Module) -> dict | None:
    """The file and sha256 of the module that defines a user's own class: model.pt records the class's import path
    and the arguments given, not its code or its defaults, so a later edit would load silently as another model."""
    try:
        file = Path(inspect.getfile(type(model)))
        return {
            "module": type(model).__module__,
            "file": file.name,
            "sha256": file_sha256(file),
        }
    except (TypeError, OSError):  # a class defined in a notebook or a REPL has no file
        return None


def _source_changed_warning(model: torch.nn.Module, meta: dict, path: Path) -> str | None:
    recorded, now = meta.get("custom_source"), custom_source(model)
    if not recorded or not now or recorded.get("sha256") == now["sha256"]:
        return None
    return (
        f"{path}: the module {recorded.get('module')} ({recorded.get('file')}) is not the one this model was trained "
        "with (its sha256 differs): if its class's code or defaults changed, the weights load into another model and "
        "it computes something else without an error. Load it with the module as it was trained"
    )


def resolve(name_or_path: str | Path) -> Path:
    """A model file, a training run's folder (its model.pt), or a shipped model's name -> the file."""
    p = Path(name_or_path)
    if p.is_file():
        return p
    if p.is_dir() and (p / "model.pt").is_file():  # a training run's folder, as ModelFileError advises
        return p / "model.pt"
    shipped = shipped_dir() / f"{name_or_path}.pt"
    if shipped.is_file():
        return shipped
    raise FileNotFoundError(
        f"model {str(name_or_path)!r}: neither a file nor a shipped model. Shipped models: "
        f"{', '.join(available_models()) or '(none)'}; or give the path of a .pt model or .ckpt checkpoint."
    )


def model_name(path: str | Path) -> str:
    """How reports name a model file: its shipped name ('euroc') when it is a shipped model, else its
    portable path (the install folder of the package differs between machines)."""
    return Path(path).stem if is_shipped(path) else portable_path(path)


def is_shipped(path: str | Path) -> bool:
    p = Path(path)
    return p.suffix == ".pt" and p.resolve().parent == shipped_dir().resolve()


NOMINAL_RATE_MATCH = 0.005  # resample_rate: a measured rate this close to the nominal one is the nominal rate
RUN_FACTS = ("dataset", "sensor", "rate_hz", "train_seqs", "train_duration_s", "train_t0_ns", "beats_calibrated")


def _run_meta(ckpt: Path) -> dict:
    """A Lightning checkpoint carries the data facts of its run but no safety verdict (known only after the fit); in
    a training run's checkpoints/ folder it takes both from the run's model.pt (the verdict is that of the model the
    run kept)."""
    model_pt = ckpt.parent.parent / "model.pt"
    if ckpt.parent.name != "checkpoints" or not model_pt.is_file():
        return {}
    meta = torch.load(model_pt, map_location="cpu", weights_only=True).get("meta", {})
    out = {k: meta[k] for k in RUN_FACTS if k in meta}
    if meta.get("calibrated_model") and (ckpt.parent.parent / meta["calibrated_model"]).is_file():
        out["calibrated_model"] = str(ckpt.parent.parent / meta["calibrated_model"])
    if out:
        out["metadata_from"] = portable_path(model_pt)
    return out


class ModelFileError(ValueError):
    """A file given as a model that is not one (the CLIs print it as one line)."""


def load_model(
    name_or_path: str | Path, map_location: str = "cpu", *, warn: bool = True
) -> tuple[CorrectionModel, dict]:
    """A shipped model's name (`available_models()`), a model file (a run's model.pt or calibrated.pt, an ensemble,
    a Lightning .ckpt) or a training run's folder -> (model in eval mode, metadata).

    The model maps (B, N, 6) raw IMU (gyro rad/s, accelerometer m/s^2) to the corrected gyro (B, N, 3); it has
    `receptive_field` (samples of history its output depends on) and `training_rate_hz` (None: unknown). The
    metadata: 'path' (the file), 'name' (how reports name it), 'model' (its config); from training, when recorded:
    'sensor' (model, rate_hz, noise densities), 'rate_hz', 'dataset', 'train_parts' (the data it saw),
    'val_aoe_deg', 'test', 'beats_calibrated' (False: the 12-parameter calibrated model fitted on the same data did
    better in validation), 'command', 'machine'.

    warn: issue a `ModelQualityWarning` when the metadata says the model did not beat the calibrated baseline
    (`not_better_warning`); callers that report it their own way pass False.
    """
    path = resolve(name_or_path)
    try:
        blob = torch.load(path, map_location=map_location, weights_only=True)
    except (FileNotFoundError, PermissionError, IsADirectoryError):
        raise
    except Exception:  # a CSV, a JSON, a truncated file: torch's unpickler fails in many ways (its message
        # advises weights_only=False, i.e. running code from the file: not advice to pass on; a truncated zip
        # can also end in a bare OSError 'Invalid argument' that names no file)
        raise ModelFileError(
            f"{path}: not a model file, or a truncated or damaged one (torch cannot read it). Give a shipped model "
            f"name ({', '.join(available_models())}), a training run's folder, its model.pt or calibrated.pt, or a "
            ".ckpt."
        ) from None
    if not isinstance(blob, dict):
        raise ModelFileError(f"{path}: not a gyrodenoise model file nor a Lightning checkpoint of one.")
    if damaged := _damaged_entry(path):
        raise ModelFileError(
            f"{path}: damaged: the bytes of its entry {damaged} no longer match their stored checksum (a copy or a "
            "disk error changed them; torch reads such weights without a word, and the corrections are garbage). "
            "Copy the file again from its source, or retrain."
        )
    if blob.get("format") == FORMAT:
        cfg, state, meta = blob["model"], blob["state_dict"], blob.get("meta", {})
    elif "state_dict" in blob and "hyper_parameters" in blob:  # Lightning checkpoint
        cfg = blob["hyper_parameters"]["model"]
        state = {k[len("model.") :]: v for k, v in blob["state_dict"].items() if k.startswith("model.")}
        # the data facts the checkpoint carries (older ones have none); the run's model.pt has the last word
        facts = blob.get("data_facts", {})
        meta = {"checkpoint": portable_path(path), "epoch": blob.get("epoch"), **facts, **_run_meta(path)}
    else:
        raise ModelFileError(f"{path}: not a gyrodenoise model file nor a Lightning checkpoint of one.")
    try:
        model = build_model(**cfg)
    except ValueError as e:  # a custom class not importable here, or a kind this version does not know
        raise ModelFileError(f"{path}: this gyrodenoise cannot build the model it holds: {e}") from None
    try:
        model.load_state_dict(state)
    except RuntimeError as e:  # a user's class whose code changed since training: its layers no longer fit
        if cfg.get("name") != "custom":
            raise
        first = str(e).splitlines()[1].strip() if len(str(e).splitlines()) > 1 else str(e)
        raise ModelFileError(
            f"{path}: the weights do not fit the class {cfg.get('_target_')} as it is now ({first}): its module "
            "changed since the model was trained; load it with the module as it was"
        ) from None
    if changed := _source_changed_warning(model, meta, path):
        warnings.warn(changed, ModelQualityWarning, stacklevel=2)
    model.eval()
    model.training_rate_hz = model_rate(meta)  # the streaming corrector checks stamps against it (None: unknown)
    # the name reports use: the shipped name, else the name the file records (ensembles), else its path
    name = Path(path).stem if is_shipped(path) else meta.get("name") or portable_path(path)
    meta = {"model": cfg, **meta, "path": str(path), "name": name}
    if warn and (msg := model_quality_warning(meta)):
        warnings.warn(msg, ModelQualityWarning, stacklevel=2)
    return model, meta


def _damaged_entry(path: Path) -> str | None:
    """The first entry of a model file (a zip archive) whose bytes fail their CRC, or None. An entry stored with CRC
    0 carries none (torch.serialization.set_crc32_options(False) writes them so) and is not judged."""
    try:
        with zipfile.ZipFile(path) as z:
            for info in z.infolist():
                if info.CRC == 0 and info.file_size > 0:
                    continue
                try:
                    z.read(info)  # checks the CRC
                except zipfile.BadZipFile:
                    return info.filename
    except (zipfile.BadZipFile, OSError):  # not a zip: torch.load has said what it could of it
        return None
    return None


class ModelQualityWarning(UserWarning):
    """A loaded model's metadata says it is worse than a simpler model."""


UNKNOWN_SENSOR = "unknown"  # dataset.sensor.model's placeholder in conf/dataset/asl_folder.yaml


def sensor_model(meta: dict) -> str | None:
    """The IMU model a model file's metadata names (its dataset's `sensor.model`); None where it names none: missing,
    empty, or asl_folder's placeholder 'unknown' (which read 'learned the errors of the mine dataset's unknown')."""
    model = (meta.get("sensor") or {}).get("model")
    return None if not model or str(model).strip().lower() == UNKNOWN_SENSOR else str(model)


def model_rate(meta: dict) -> float | None:
    """Training rate of a model, from its metadata (None when unknown)."""
    rate = meta.get("rate_hz") or (meta.get("sensor") or {}).get("rate_hz")
    return float(rate) if rate else None


def resample_rate(meta: dict) -> float | None:
    """The rate `correct --resample` puts a recording on: the sensor's nominal rate where the rate measured on the
    training stamps is within `NOMINAL_RATE_MATCH` of it (EuRoC's clock runs at 200.0026 Hz: a user asks for 200),
    else the measured rate (a nominal rate the data did not have is no target)."""
    measured, nominal = model_rate(meta), (meta.get("sensor") or {}).get("rate_hz")
    if nominal and (measured is None or abs(measured / float(nominal) - 1) <= NOMINAL_RATE_MATCH):
        return float(nominal)
    return measured


def _label(meta: dict) -> str:
    """How a warning names the model: its recorded name, else its path."""
    return meta.get("name", meta.get("path", "this model"))


def model_quality_warning(meta: dict) -> str | None:
    """The warnings a model's metadata calls for, as one message: it did not beat the calibrated baseline, or it reads
    future samples (`causal: false`, measured when a user's own network was trained). None when neither."""
    said = [w for w in (not_causal_warning(meta), not_better_warning(meta)) if w]
    return "; ".join(said) or None


def not_causal_warning(meta: dict) -> str | None:
    """The warning for a model whose training measured that it reads future samples (`causal: false`), else None."""
    causal = meta.get("causal")
    members = meta.get("members_causal") or []
    if causal is not False and False not in members:
        return None
    which = "" if causal is False else f" ({members.count(False)} of its {len(members)} members)"
    return (
        f"model {_label(meta)}{which} is not causal: its training found its corrections moved by later samples "
        "(models.build.causality_leak), so its figures are optimistic and it cannot run onboard, where later samples "
        "do not exist yet"
    )


def calibrated_beside(model_path: str | Path, name: str | None) -> str | None:
    """The calibrated baseline a model's metadata names (`calibrated_model`: a file name beside the model file, or a
    path) as a path, where that file is; None otherwise."""
    if not name:
        return None
    found = Path(name) if Path(name).is_absolute() else Path(model_path).parent / name
    return str(found) if found.is_file() else None


def not_better_warning(meta: dict) -> str | None:
    """The warning for a model whose metadata says it did not beat the calibrated baseline, else None."""
    members = meta.get("members_beat_calibrated") or []
    # an ensemble is not compared as a whole when it is built; all its members failing is the same warning
    all_members_failed = meta.get("beats_calibrated") is None and members and all(b is False for b in members)
    if meta.get("beats_calibrated") is not False and not all_members_failed:
        return None
    name = _label(meta)
    model_val, cal_val = meta.get("val_aoe_deg"), meta.get("calibrated_val_aoe_deg")
    if all_members_failed:
        model_val, name = meta.get("member_val_aoe_deg_mean"), f"{name} (none of its {len(members)} members)"
    numbers = ""
    if model_val is not None and cal_val is not None:
        numbers = (
            f" (validation AOE {float(model_val):.2f} deg vs {float(cal_val):.2f} deg for the calibrated baseline "
            "fitted on the same data)"
        )
    instead = meta.get("calibrated_model")
    if instead and meta.get("path"):  # recorded as a file name beside the model file: say where it is
        instead = calibrated_beside(meta["path"], instead) or instead
    if not instead and all_members_failed:  # the baseline fitted with a member on its data, not a shipped one
        fitted = [r["calibrated_model"] for r in meta.get("members") or [] if r.get("calibrated_model")]
        instead = fitted[0] if fitted else None
    shipped, dataset = available_models(), meta.get("dataset")
    if (
        not instead
        and dataset in shipped
        and dataset != name
        and load_model(dataset, warn=False)[1]["model"]["name"] == "calibrated"
    ):
        instead = dataset  # the dataset's default is the calibrated model (TUM-VI): name the default, not a variant
    if not instead and dataset and f"{dataset}-calibrated" in shipped:
        instead = f"{dataset}-calibrated"
    advice = (
        f"use the calibrated model {instead!r} instead"
        if instead
        else "use a calibrated model (python -m gyrodenoise.train model=calibrated ...) instead"
    )
    return f"model {name} did not beat the 12-parameter calibrated baseline on its validation data{numbers}: {advice}."


def training_overlap_warning(
    meta: dict, parts: list[tuple[str, float]], first_stamps_ns: list[int] | None = None
) -> str | None:
    """The warning for scoring a model on data it was trained on, else None.

    parts: (sequence name, start in seconds) of each evaluated part. A model trained on the first
    `train_duration_s` of its `train_seqs` (None: the whole sequences) overlaps a part of one of them that
    starts before that time. Metadata without `train_seqs` (older files, user models) cannot be checked.
    first_stamps_ns: each part's recording's first IMU stamp; where the model recorded that of its training
    recording of the same name (`train_t0_ns`) and they differ, the part is another recording (own data often
    reuses names such as seq01).
    """
    trained = meta.get("train_seqs") or []
    duration = meta.get("train_duration_s")
    recorded = meta.get("train_t0_ns") or {}
    stamps = first_stamps_ns if first_stamps_ns is not None else [None] * len(parts)
    seen = [
        n
        for (n, start), t0 in zip(parts, stamps, strict=True)
        if n in trained
        and (duration is None or start < float(duration))
        and (t0 is None or n not in recorded or int(recorded[n]) == int(t0))
    ]
    if not seen:
        return None
    name = _label(meta)
    span = "whole" if duration is None else f"first {float(duration):g} s"
    return (
        f"model {name} was trained on the {span} of {', '.join(dict.fromkeys(seen))}: its figures there are "
        "training figures, not held-out ones (evaluate it on sequences it did not see, e.g. a cross-validation fold)."
    )


def other_imu_warning(
    meta: dict,
    dataset: str,
    sensor: dict | None = None,
    root: str | Path | None = None,
    setting: str = "weights.proposed",
) -> str | None:
    """The warning for scoring a model on a dataset it was not trained on, unless both name the same IMU model
    (own recordings of the same sensor) or the data come from the folder it was trained on (the same recordings under
    another `dataset.name`); None when the metadata does not say (older files). `setting`: the option that names
    the model."""
    trained = meta.get("dataset")
    if not trained or trained == dataset:
        return None
    if root is not None and meta.get("data_root") == str(Path(root).resolve()):
        return None
    model_sensor, data_sensor = sensor_model(meta), sensor_model({"sensor": sensor})
    if model_sensor and model_sensor == data_sensor:
        return None
    imu = f" ({model_sensor})" if model_sensor else ""
    name = _label(meta)
    return (
        f"model {name} was trained on {trained}{imu}, not on {dataset}: it learned the errors of another IMU, so "
        f"its figures here say little about the method (train one on {dataset}, or pass {setting}=...)."
    )


def other_rate_warning(model: CorrectionModel, meta: dict, rates: dict[str, float]) -> str | None:
    """The warning for scoring a model with memory on sequences sampled at another rate than it was trained at
    (more than checks.RATE_TOL apart): its convolutions span a fixed number of samples. `rates`: name -> Hz. A
    memoryless model (the calibrated one) does not depend on the rate; an unknown training rate cannot be checked."""
    trained = model_rate(meta)
    if not trained or int(getattr(model, "receptive_field", 1)) <= 1:
        return None
    off = {n: r for n, r in rates.items() if abs(r / trained - 1.0) > RATE_TOL}
    if not off:
        return None
    name = _label(meta)
    listed = ", ".join(f"{n} {r:.4g} Hz" for n, r in off.items())
    return (
        f"model {name} was trained at {trained:.4g} Hz but {listed}: its convolutions span a fixed number of samples, "
        "so it sees another time window and noise level there. Resample the data to the training rate, or train a "
        "model at this rate."
    )
