# gyrodenoise in a container. The default command runs the test suite.
#
# CPU (default):
#   docker build -t gyrodenoise .
#   docker run --rm gyrodenoise                                   # tests (real-data tests skip)
#   docker run --rm -v /path/to/data:/data:ro gyrodenoise         # with euroc/ and tumvi/ under /data
#   docker run --rm -v $PWD:/work -w /work gyrodenoise gyrodenoise-correct imu.csv -m euroc -o out
#
# CUDA: the same image with PyTorch's CUDA wheels (they bring the CUDA runtime; the host needs the
# NVIDIA driver and the container toolkit). Pick the CUDA variant that the PyTorch index offers for
# TORCH_VERSION, e.g.:
#   docker build --build-arg TORCH_INDEX=https://download.pytorch.org/whl/cu128 -t gyrodenoise:cuda .
#   docker run --rm --gpus all gyrodenoise:cuda python -m gyrodenoise.train trainer=gpu
# Another base image (e.g. an NVIDIA one that already has Python 3.10+): --build-arg BASE=...

ARG BASE=python:3.11-slim
FROM ${BASE}

ARG TORCH_VERSION=2.13.0
ARG TORCH_INDEX=https://download.pytorch.org/whl/cpu

ENV PYTHONDONTWRITEBYTECODE=1 \
    PYTHONUNBUFFERED=1 \
    PIP_NO_CACHE_DIR=1 \
    PIP_DISABLE_PIP_VERSION_CHECK=1 \
    GYRODENOISE_DATA=/data \
    MPLBACKEND=Agg

# torch first, from the index of the wanted build (CPU by default); the package's "torch>=..."
# requirement is then already satisfied and pip does not fetch the default (CUDA) wheel
RUN pip install "torch==${TORCH_VERSION}" --index-url "${TORCH_INDEX}"

WORKDIR /app
COPY . /app
RUN pip install ".[dev,export,sweep,slurm]" \
    && useradd --create-home --uid 1000 gyro \
    && chown -R gyro /app
USER gyro

CMD ["python", "-m", "pytest", "-q", "tests"]
