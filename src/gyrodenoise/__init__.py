"""gyrodenoise: learn to denoise a low-cost IMU gyroscope; open-loop attitude estimation."""

__version__ = "0.1.0"
