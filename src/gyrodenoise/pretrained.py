"""Save and load trained correction models: shipped weights by name, or files.

A model file is a plain torch dict (loads with weights_only=True): the model's config values, its
state dict (normalisation statistics included) and metadata (dataset, split, metrics, command).
Lightning checkpoints of DenoiserModule load too.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

import torch

from gyrodenoise.atomic import atomic_path
from gyrodenoise.models.denoiser import GyroCorrection, build_model
from gyrodenoise.paths import portable_path

FORMAT = "gyrodenoise-model/1"


def shipped_dir() -> Path:
    return Path(str(resources.files("gyrodenoise") / "weights"))


def available_models() -> list[str]:
    return sorted(p.stem for p in shipped_dir().glob("*.pt"))


def save_model(model: GyroCorrection, model_cfg: dict, path: str | Path, meta: dict | None = None) -> Path:
    """Write atomically: an interrupted save never leaves a file that looks whole."""
    path = Path(path)
    payload = {
        "format": FORMAT,
        "model": dict(model_cfg),
        "state_dict": {k: v.detach().cpu() for k, v in model.state_dict().items()},
        "meta": dict(meta or {}),
    }
    with atomic_path(path) as tmp:
        torch.save(payload, tmp)
    return path


def resolve(name_or_path: str | Path) -> Path:
    p = Path(name_or_path)
    if p.is_file():
        return p
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
    p = Path(path)
    if p.suffix == ".pt" and p.resolve().parent == shipped_dir().resolve():
        return p.stem
    return portable_path(p)


def load_model(name_or_path: str | Path, map_location: str = "cpu") -> tuple[GyroCorrection, dict]:
    """Returns (model in eval mode, metadata); metadata 'path' is the file, 'name' how reports name it."""
    path = resolve(name_or_path)
    blob = torch.load(path, map_location=map_location, weights_only=True)
    if blob.get("format") == FORMAT:
        cfg, state, meta = blob["model"], blob["state_dict"], blob.get("meta", {})
    elif "state_dict" in blob and "hyper_parameters" in blob:  # Lightning checkpoint
        cfg = blob["hyper_parameters"]["model"]
        state = {k[len("model.") :]: v for k, v in blob["state_dict"].items() if k.startswith("model.")}
        meta = {"checkpoint": portable_path(path), "epoch": blob.get("epoch")}
    else:
        raise ValueError(f"{path}: not a gyrodenoise model file nor a Lightning checkpoint of one.")
    model = build_model(**cfg)
    model.load_state_dict(state)
    model.eval()
    return model, {"model": cfg, **meta, "path": str(path), "name": model_name(path)}
