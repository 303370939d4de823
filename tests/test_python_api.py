"""gyrodenoise used as a library: the top-level names, checked array inputs, and train() called from Python leaving
the caller's process as it found it."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
from hydra.errors import ConfigCompositionException
from scipy.spatial.transform import Rotation
from test_train import config, tiny_dataset

import gyrodenoise as gd
from gyrodenoise.data.checks import SanityCheckError
from gyrodenoise.models.ensemble import predict_with_spread
from gyrodenoise.pretrained import resolve
from gyrodenoise.so3 import exp
from gyrodenoise.train import train


def test_the_top_level_names_resolve_without_importing_torch_up_front():
    for name in gd.__all__:
        assert getattr(gd, name) is not None
    code = "import sys, gyrodenoise; print('torch' in sys.modules, 'lightning' in sys.modules)"
    assert subprocess.run([sys.executable, "-c", code], capture_output=True, text=True).stdout.split() == [
        "False",
        "False",
    ]
    with pytest.raises(AttributeError, match="no attribute 'nope'"):
        gd.nope  # noqa: B018


def recording(n: int = 2000, rate: float = 200.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(0)
    t = 1.4e9 + np.arange(n) / rate
    gyro = 0.3 * np.sin(np.arange(n)[:, None] / 50.0 + np.arange(3)) + 0.01 * rng.standard_normal((n, 3))
    acc = np.array([0.0, 0.0, 9.81]) + 0.05 * rng.standard_normal((n, 3))
    return t, gyro, acc


def test_correct_arrays_checks_units_and_shapes_and_names_its_own_arguments():
    t, gyro, acc = recording()
    c = gd.correct_arrays(t, gyro, acc, "euroc-calibrated")
    assert c.gyro.shape == (len(t), 3) and c.R.shape == (len(t), 3, 3)
    t_ns = np.round(t * 1e9).astype(np.int64)
    exact = gd.correct_arrays(t_ns, gyro, acc, "euroc-calibrated", time_unit="ns")
    assert exact.rec.t_ns[0] == t_ns[0]  # integer stamps kept to the nanosecond
    with pytest.raises(SanityCheckError, match=r"gyro_unit='deg/s'.*force=True"):
        gd.correct_arrays(t, np.degrees(gyro) * 20, acc, "euroc-calibrated")
    with pytest.raises(SanityCheckError, match="acc_unit='g'"):
        gd.correct_arrays(t, gyro, acc / 9.81, "euroc-calibrated")
    with pytest.raises(ValueError, match=r"pass gyro\.T"):
        gd.correct_arrays(t, gyro.T, acc, "euroc-calibrated")
    with pytest.raises(ValueError, match="time_unit='min'"):
        gd.correct_arrays(t, gyro, acc, "euroc-calibrated", time_unit="min")
    bad = gyro.copy()
    bad[100, 1] = np.nan  # it was "imu: 1 rows hold NaN/inf", naming neither the argument nor the row
    with pytest.raises(ValueError, match=r"gyro\[100, 1\] is nan \(row 101"):
        gd.correct_arrays(t, bad, acc, "euroc-calibrated")


def test_correct_arrays_refuses_float32_stamps_that_lost_their_time():
    """float32 keeps 24 bits: absolute stamps in s (1.4e9) were rounded to 128 s and refused as 'duplicated timestamps'
    with advice to drop them (drop_duplicates=True); stamps 3000 s into a recording, rounded to 244 us, were taken
    without a word as a 200 Hz clock jittering by 5 %. Short float32 stamps, exact enough, still read."""
    t, gyro, acc = recording()
    with pytest.raises(ValueError, match=r"t is float32: .*rounds stamps near 1\.4e\+09 s to 128 s.*float64"):
        gd.correct_arrays(t.astype(np.float32), gyro, acc, "euroc-calibrated")
    with pytest.raises(ValueError, match=r"t is float32: .*to 0\.000244 s, 4\.9 % of the mean step"):
        gd.correct_arrays((t - t[0] + 3000.0).astype(np.float32), gyro, acc, "euroc-calibrated")
    short = gd.correct_arrays((t - t[0]).astype(np.float32), gyro, acc, "euroc-calibrated")
    assert len(short.rec) == len(t)


def test_the_python_api_pages_first_example_runs(monkeypatch):
    """docs/python-api.md's first block, as written (it used seq.t_ns, which Sequence lacked)."""
    from conftest import DATA_ROOT, require_data

    require_data("euroc", "MH_02_easy")
    monkeypatch.setenv("GYRODENOISE_DATA", str(DATA_ROOT))
    text = (Path(__file__).parents[1] / "docs" / "python-api.md").read_text()
    block = text.split("```python\n", 1)[1].split("```", 1)[0]
    scope: dict = {}
    exec(compile(block, "docs/python-api.md", "exec"), scope)  # noqa: S102
    assert np.allclose(scope["c"].gyro, scope["gyro"], atol=1e-6) and abs(scope["aoe_3d"] - 4.94) < 0.005


def test_array_functions_refuse_what_they_would_get_wrong_silently():
    model, _ = gd.load_model("euroc-calibrated")
    imu = np.zeros((50, 6))
    with pytest.raises(ValueError, match=r"pass imu\.T"):
        predict_with_spread(model, imu[:10].T)
    imu[3, 0] = np.nan
    with pytest.raises(ValueError, match="1 rows hold NaN"):
        predict_with_spread(model, imu)
    gyro = np.zeros((10, 3))
    R = gd.integrate_gyro(np.eye(3), gyro + [0.0, 0.0, 1.0], 0.005)  # one period for all samples
    assert np.isclose(Rotation.from_matrix(R[-1]).magnitude(), 9 * 0.005)
    with pytest.raises(ValueError, match="were timestamps"):
        gd.integrate_gyro(np.eye(3), gyro, 1.4e9 + np.arange(10) * 0.005)
    with pytest.raises(ValueError, match=r"pass gyro\.T"):
        gd.integrate_gyro(np.eye(3), gyro.T, 0.005)
    q = Rotation.random(10, random_state=0).as_quat()
    with pytest.raises(ValueError, match="quaternions"):
        gd.aoe(q, q)
    with pytest.raises(TypeError, match="from_rotvec"):
        exp(np.zeros(3))


def test_a_misspelt_key_from_python_names_the_key_it_meant():
    with pytest.raises(ConfigCompositionException, match="did you mean trainer.max_epochs"):
        gd.compose_config("train", ["trainer.max_epoch=3"])


def test_train_from_python_needs_an_output_folder_and_restores_the_thread_count(tiny_asl_root, tmp_path):
    no_dir = gd.compose_config("train", tiny_dataset(tiny_asl_root))  # paths.output_dir: Hydra's run folder
    with pytest.raises(ValueError, match=r"paths.output_dir=outputs/my_run"):
        train(no_dir)
    before = torch.get_num_threads()
    want = 1 if before != 1 else 2
    summary = train(config(tiny_asl_root, tmp_path / "run", f"threads={want}"))
    assert torch.get_num_threads() == before
    assert summary["command"].startswith("gyrodenoise.train.train(cfg) called from Python")
    assert resolve(tmp_path / "run") == tmp_path / "run" / "model.pt"  # a run's folder is a model
    model, meta = gd.load_model(tmp_path / "run")
    assert meta["command"] == summary["command"]
