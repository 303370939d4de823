from gyrodenoise.models.denoiser import CalibratedImu, DilatedCNNDenoiser, GyroCorrection, build_model

__all__ = ["CalibratedImu", "DilatedCNNDenoiser", "GyroCorrection", "build_model"]
