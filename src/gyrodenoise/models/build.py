"""Models from plain config values: the one place that knows every model kind (single networks in
denoiser.py, ensembles of them in ensemble.py, a user's own class), so that neither of those imports the other
back."""

from __future__ import annotations

import importlib
import inspect
import math
import numbers

import torch
from torch import nn

from gyrodenoise.models.denoiser import CalibratedImu, DilatedCNNDenoiser, GyroCorrection
from gyrodenoise.models.ensemble import EnsembleCorrection

KINDS = ("denoiser", "calibrated", "ensemble", "custom")
CUSTOM_CONTRACT = (
    "a custom model is a subclass of gyrodenoise.models.GyroCorrection whose correction(imu) maps raw IMU (B, N, 6) "
    "to a causal gyro correction (B, N, 3) in rad/s (output n from samples <= n) and that sets "
    "self.receptive_field, the number of past samples an output depends on (docs/training.md, 'Your own network')"
)


def build_model(name: str = "denoiser", **kwargs) -> nn.Module:
    """Build a model from plain config values (what checkpoints and shipped weights store).

    name="ensemble" takes `members`, a list of such configs, and optionally `spread_scale` (see
    models/ensemble.py). name="custom" takes `_target_`, the import path of a user's GyroCorrection subclass, and
    that class's own arguments.
    """
    if "_target_" in kwargs and name != "custom":
        raise ValueError(f"model._target_ is given with model.name={name!r}: a user's own class needs name: custom")
    if name == "ensemble":
        members = kwargs.pop("members", None)
        spread_scale = kwargs.pop("spread_scale", 1.0)
        if kwargs or not members:
            raise ValueError(
                f"the ensemble model takes a non-empty `members` list and `spread_scale`, got {sorted(kwargs)}"
            )
        return EnsembleCorrection([build_model(**dict(cfg)) for cfg in members], spread_scale)
    if name == "denoiser":
        return _construct(DilatedCNNDenoiser, "denoiser", kwargs)
    if name == "calibrated":
        return _construct(CalibratedImu, "calibrated", kwargs)
    if name == "custom":
        return _custom(**kwargs)
    raise ValueError(f"model.name={name!r}; choose one of {', '.join(repr(k) for k in KINDS)}")


_VAR = (inspect.Parameter.VAR_POSITIONAL, inspect.Parameter.VAR_KEYWORD)


def _construct(cls: type, kind: str, kwargs: dict) -> nn.Module:
    """cls(**kwargs), a key the class does not take named with the ones it does (not a TypeError traceback)."""
    params = inspect.signature(cls.__init__).parameters
    takes_any = any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params.values())
    known = [p for p in params if p != "self" and params[p].kind is not inspect.Parameter.VAR_KEYWORD]
    where = f"the {kind} model ({cls.__module__}.{cls.__qualname__})"
    if not takes_any and (unknown := sorted(set(kwargs) - set(known))):
        raise ValueError(f"model.{unknown[0]} is not a parameter of {where}; it takes {', '.join(known) or 'none'}")
    required = [p for p in known if params[p].default is inspect.Parameter.empty and params[p].kind not in _VAR]
    if missing := [p for p in required if p not in kwargs]:
        raise ValueError(
            f"{where} needs model.{missing[0]} (required: {', '.join(required)}): add +model.{missing[0]}=..."
        )
    return cls(**kwargs)


def _custom(_target_: str | None = None, **kwargs) -> GyroCorrection:
    if not _target_ or str(_target_) == "???":
        raise ValueError(
            f"model.name=custom needs model._target_, the class's import path (e.g. mynets.MyNet); {CUSTOM_CONTRACT}"
        )
    if "." not in str(_target_):
        raise ValueError(f"model._target_={_target_}: give the class with its module, e.g. mynets.{_target_}")
    module_name, _, cls_name = str(_target_).rpartition(".")
    try:
        cls = getattr(importlib.import_module(module_name), cls_name)
    except (ImportError, AttributeError) as e:
        missing = e.name if isinstance(e, ModuleNotFoundError) else None
        if missing and not module_name.startswith(missing) and not missing.startswith(module_name):
            raise ValueError(  # the module was found; something it imports is not installed
                f"model._target_={_target_}: its module {module_name} imports {missing}, which is not installed here: "
                "install it where the command runs"
            ) from None
        raise ValueError(
            f"model._target_={_target_}: cannot import it ({e}). The module must be importable where the command runs "
            "(installed, or its folder on PYTHONPATH), also later for evaluate, correct and export"
        ) from None
    if not (isinstance(cls, type) and issubclass(cls, GyroCorrection)):
        raise ValueError(f"model._target_={_target_} is not a GyroCorrection subclass: {CUSTOM_CONTRACT}")
    model = _construct(cls, "custom", kwargs)
    rf = getattr(model, "receptive_field", None)
    if isinstance(rf, bool) or not isinstance(rf, numbers.Integral) or rf < 1:
        raise ValueError(
            f"model._target_={_target_}: receptive_field={rf!r}; set it in __init__ to a positive int (for a recurrent "
            f"network, a bound on its memory in samples): {CUSTOM_CONTRACT}"
        )
    if type(rf) is not int:  # a numpy integer: the exporters' metadata and slices want a plain int
        model.receptive_field = int(rf)
    _check_correction_shape(model, str(_target_))
    return model


@torch.no_grad()
def _check_correction_shape(model: GyroCorrection, target: str) -> None:
    """One dry call before any training: a correction of another shape failed deep inside the first training step
    (a traceback from Lightning's model summary), and a (B, N, 1) or (B, 1, 3) one was broadcast silently."""
    # its own generator, eval mode: the global random stream (seeded runs) and batch-norm statistics stay as they are
    x = model.mean + model.std * torch.randn(2, 37, 6, generator=torch.Generator().manual_seed(0))
    was_training = model.training
    model.eval()
    try:
        out = model.correction(x)
    except Exception as e:  # noqa: BLE001 - the user's code: its message, in one line, with the contract
        raise ValueError(
            f"model._target_={target}: correction() on raw IMU of shape (2, 37, 6) failed ({type(e).__name__}: {e}): "
            f"{CUSTOM_CONTRACT}"
        ) from None
    finally:
        model.train(was_training)
    if not isinstance(out, torch.Tensor) or tuple(out.shape) != (2, 37, 3):
        got = tuple(out.shape) if isinstance(out, torch.Tensor) else type(out).__name__
        raise ValueError(
            f"model._target_={target}: correction() of raw IMU (2, 37, 6) returned {got}, not (2, 37, 3) (batch, "
            f"samples, axes): {CUSTOM_CONTRACT}"
        )


@torch.no_grad()
def causality_leak(model: nn.Module, n: int | None = None, seed: int = 0) -> float:
    """How much the corrections before the middle of a random input move when only the samples after it change,
    relative to how much the corrections after the middle move when only the samples before it change (the model's
    own sensitivity to its input). 0, to float rounding, for a causal model; about 1 for one that reads the future
    as much as the past; NaN when the model outputs NaN. The changed samples are redrawn, tripled and shifted by two
    standard deviations, so that statistics over a window (a mean, a normalisation over time, a pooling) move too: a
    redraw from the same distribution left them almost where they were. A model that reads the future scores its
    test optimistically and cannot run onboard; built-in models are causal by construction."""
    rf = int(getattr(model, "receptive_field", 1))
    n = n or max(4 * rf, 1000)
    h = n // 2
    gen = torch.Generator().manual_seed(seed)
    mean, std = model.mean.detach().cpu(), model.std.detach().cpu()
    x = mean + std * torch.randn(1, n, 6, generator=gen)

    def changed(part: slice) -> torch.Tensor:
        y = x.clone()
        y[:, part] = mean + 2 * std + 3 * std * torch.randn(y[:, part].shape, generator=gen)
        return y

    was_training = model.training
    model.eval()
    device = next(model.buffers()).device
    correction = getattr(model, "correction", None) or (lambda z: model(z) - z[..., :3])
    base = correction(x.to(device)).cpu()
    future = float((correction(changed(slice(h, None)).to(device)).cpu()[:, :h] - base[:, :h]).abs().max())
    past = float((correction(changed(slice(None, h)).to(device)).cpu()[:, h:] - base[:, h:]).abs().max())
    model.train(was_training)
    return future / max(past, 1e-9) if math.isfinite(past) else math.nan


def not_built_in(model: nn.Module) -> str | None:
    """'the model (pkg.Class)' or 'member k (pkg.Class)' for the first model or ensemble member that is not exactly a
    built-in denoiser or calibrated model (a subclass included: its `correction` may be another function), or None.
    The forms that rebuild the built-in arithmetic (streaming, stateful graph, C) refuse such a model."""
    members = list(model.members) if isinstance(model, EnsembleCorrection) else [model]
    for k, m in enumerate(members):
        if type(m) not in (DilatedCNNDenoiser, CalibratedImu):
            what = f"member {k}" if isinstance(model, EnsembleCorrection) else "the model"
            return f"{what} ({type(m).__module__}.{type(m).__qualname__})"
    return None


def check_stream_form(model: nn.Module) -> None:
    """Refuse a model (or an ensemble member) that the streaming corrector and the stateful export cannot reproduce:
    they rebuild exactly the built-in denoiser's and calibrated model's arithmetic, so a subclass or a user's own
    class would stream something else without an error."""
    if what := not_built_in(model):
        raise ValueError(
            f"{what} has no streaming form: the streaming corrector and the stateful ONNX graph implement the "
            "built-in denoiser and calibrated models only. Use the batch path (correct --engine batch; export "
            "without --stateful; predict_gyro on a window)"
        )
