"""Shared fixtures. Real-data tests read ../shared/data; they skip when it is absent, except under CI
(CI=true), where a missing data folder is a failure."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
DATA_ROOT = Path(os.environ.get("GYRODENOISE_DATA", REPO.parent / "shared" / "data"))


def pytest_configure(config: pytest.Config) -> None:
    """With parallel workers (`-n`, pytest-xdist) each worker gets one thread for torch, BLAS and the FFTs
    (`gyrodenoise.fft_threads`), set here before the workers start so that they and the processes they spawn inherit
    it: two workers of two threads each on two cores ran the suite 1.2 times faster than one worker, not 2."""
    if getattr(config.option, "numprocesses", None) and not os.environ.get("PYTEST_XDIST_WORKER"):
        for var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
            os.environ.setdefault(var, "1")


def require_data(*parts: str) -> Path:
    """Path under the shared data folder, or skip (fail under CI) when it is missing."""
    path = DATA_ROOT.joinpath(*parts)
    if not path.exists():
        msg = f"real data not found at {path} (set GYRODENOISE_DATA to the folder holding euroc/ and tumvi/)"
        if os.environ.get("CI", "").lower() == "true":
            pytest.fail(msg)
        pytest.skip(msg)
    return path


@pytest.fixture(scope="session")
def euroc_root() -> Path:
    return require_data("euroc")


@pytest.fixture(scope="session")
def tumvi_root() -> Path:
    return require_data("tumvi")


@pytest.fixture(scope="session")
def tiny_asl_root(tmp_path_factory) -> Path:
    """Three 6-s synthetic sequences a, b, c in the ASL layout (tests that train or read on tiny data)."""
    from _asl import write_asl_sequence

    root = tmp_path_factory.mktemp("asl_tiny")
    for i, name in enumerate(["a", "b", "c"]):
        write_asl_sequence(root / name, seconds=6.0, seed=10 + i)
    return root


@pytest.fixture(autouse=True)
def _isolated_cache(tmp_path_factory, monkeypatch):
    """Keep the preprocessing cache of tests out of the user's home."""
    monkeypatch.setenv("GYRODENOISE_CACHE", str(tmp_path_factory.getbasetemp() / "cache"))


@pytest.fixture(scope="session")
def compiler() -> str:
    """The host C compiler the C export's tests build with (they skip, saying why, without one)."""
    from gyrodenoise.c_export import find_c_compiler

    cc = find_c_compiler()
    if cc is None:
        pytest.skip("no C compiler found (cc, gcc, clang or $CC): the C export cannot be compiled and compared")
    return cc
