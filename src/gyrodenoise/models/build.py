"""Models from plain config values: the one place that knows every model kind (single networks in
denoiser.py, ensembles of them in ensemble.py), so that neither of those imports the other back."""

from __future__ import annotations

from torch import nn

from gyrodenoise.models.denoiser import CalibratedImu, DilatedCNNDenoiser
from gyrodenoise.models.ensemble import EnsembleCorrection


def build_model(name: str = "denoiser", **kwargs) -> nn.Module:
    """Build a model from plain config values (what checkpoints and shipped weights store).

    name="ensemble" takes `members`, a list of such configs, and optionally `spread_scale` (see
    models/ensemble.py).
    """
    if name == "ensemble":
        members = kwargs.pop("members", None)
        spread_scale = kwargs.pop("spread_scale", 1.0)
        if kwargs or not members:
            raise ValueError(
                f"the ensemble model takes a non-empty `members` list and `spread_scale`, got {sorted(kwargs)}"
            )
        return EnsembleCorrection([build_model(**dict(cfg)) for cfg in members], spread_scale)
    if name == "denoiser":
        return DilatedCNNDenoiser(**kwargs)
    if name == "calibrated":
        if set(kwargs) - {"g_sensitivity"}:
            raise ValueError(f"the calibrated model takes only `g_sensitivity`, got {sorted(kwargs)}")
        return CalibratedImu(**kwargs)
    raise ValueError(f"model.name={name!r}; choose 'denoiser', 'calibrated' or 'ensemble'")
