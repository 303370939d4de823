from gyrodenoise.models.build import build_model
from gyrodenoise.models.denoiser import CalibratedImu, DilatedCNNDenoiser, GyroCorrection
from gyrodenoise.models.ensemble import CorrectionModel, EnsembleCorrection

__all__ = [
    "CalibratedImu",
    "CorrectionModel",
    "DilatedCNNDenoiser",
    "EnsembleCorrection",
    "GyroCorrection",
    "build_model",
]
