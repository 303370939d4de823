"""Ensembles (models/ensemble.py, gyrodenoise.ensemble), their uncertainty output and its calibration
check (gyrodenoise.uncertainty), and the calibrated-baseline safety net (gyrodenoise.baseline)."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest
import torch
from _asl import run_train
from _models import random_imu, random_model
from scipy.spatial.transform import Rotation

from gyrodenoise import ensemble as ensemble_cli
from gyrodenoise.baseline import evaluate_on, fit_calibrated, safety_meta
from gyrodenoise.correct import main as correct_main
from gyrodenoise.data.readers import read_imu
from gyrodenoise.data.sequence import Sequence
from gyrodenoise.evaluate import load_checked
from gyrodenoise.models.build import build_model
from gyrodenoise.models.denoiser import CalibratedImu, predict_gyro
from gyrodenoise.models.ensemble import EnsembleCorrection, predict_with_spread
from gyrodenoise.pretrained import ModelQualityWarning, available_models, load_model, not_better_warning, save_model
from gyrodenoise.so3 import integrate_gyro
from gyrodenoise.streaming import StreamingCorrector
from gyrodenoise.uncertainty import calibration

TINY = {"channels": (8, 16), "kernel_size": 5, "dilations": (1, 4)}
# float32 network; the streaming corrector folds batch norm and sums in another order, the ONNX
# runtime uses its own kernels: the same tolerances as the single-model parity tests
STREAM_ATOL, ONNX_ATOL = 2e-5, 1e-5  # rad/s


def calibrated_model(seed: int) -> CalibratedImu:
    g = torch.Generator().manual_seed(seed)
    m = CalibratedImu()
    m.bias.data = 0.02 * torch.randn(3, generator=g)
    m.C_delta.data = 0.01 * torch.randn(3, 3, generator=g)
    return m.eval()


def members() -> list:
    """A mix: two small denoisers of different shapes and a calibrated model."""
    return [
        random_model(seed=1, **TINY),
        random_model(seed=2, channels=(4, 8, 8), kernel_size=3, dilations=(1, 2, 8)),
        calibrated_model(3),
    ]


def cfgs() -> list[dict]:
    return [
        {"name": "denoiser", **TINY},
        {"name": "denoiser", "channels": (4, 8, 8), "kernel_size": 3, "dilations": (1, 2, 8)},
        {"name": "calibrated"},
    ]


def run_model(model, imu: np.ndarray) -> torch.Tensor:
    with torch.no_grad():
        return model(torch.as_tensor(imu, dtype=torch.float32)[None])[0]


# ------------------------------------------------------------------ the model


def test_one_member_equals_the_model_exactly():
    m = random_model(seed=5, **TINY)
    ens = EnsembleCorrection([m]).eval()
    imu = random_imu(500)
    x = torch.as_tensor(imu, dtype=torch.float32)[None]
    with torch.no_grad():
        mean, std = ens.forward_with_spread(x)
        assert torch.equal(mean, m(x)) and torch.equal(ens(x), m(x))
    assert std.isnan().all()  # one member measures no spread: not a zero that reads as certainty
    assert predict_with_spread(ens, imu)[1] is None
    sc = StreamingCorrector(ens)
    assert sc.push_chunk_with_spread(imu[:50])[1] is None and sc.push_with_spread(imu[50])[1] is None
    assert ens.receptive_field == m.receptive_field
    assert torch.equal(ens.C_hat, m.C_hat)


def test_two_members_mean_and_std_by_hand():
    a, b = random_model(seed=1, **TINY), calibrated_model(7)
    ens = EnsembleCorrection([a, b]).eval()
    imu = random_imu(400)
    wa, wb = run_model(a, imu).double(), run_model(b, imu).double()
    mean, std = predict_with_spread(ens, imu)
    np.testing.assert_allclose(mean, ((wa + wb) / 2).numpy(), atol=1e-6)
    np.testing.assert_allclose(std, ((wa - wb).abs() / np.sqrt(2)).numpy(), atol=1e-6)  # sample std, K=2
    assert std.min() >= 0 and np.abs(wa - wb).max() > 1e-2  # the members do differ
    np.testing.assert_allclose(predict_gyro(ens, imu).numpy(), mean, atol=0)
    assert ens.receptive_field == a.receptive_field
    # C_hat is the members' mean: mean - C_hat w_imu is the mean of the members' corrections
    w_tilde = mean - imu[:, :3] @ ens.C_hat.detach().double().numpy().T
    ta = wa.numpy() - imu[:, :3] @ a.C_hat.detach().double().numpy().T
    tb = wb.numpy() - imu[:, :3] @ b.C_hat.detach().double().numpy().T
    np.testing.assert_allclose(w_tilde, (ta + tb) / 2, atol=1e-5)


def test_bad_members():
    with pytest.raises(ValueError, match="at least one"):
        EnsembleCorrection([])
    with pytest.raises(TypeError, match="not a GyroCorrection"):
        EnsembleCorrection([torch.nn.Linear(6, 3)])
    with pytest.raises(TypeError, match="itself an ensemble"):
        EnsembleCorrection([EnsembleCorrection([calibrated_model(0)])])
    with pytest.raises(ValueError, match="members"):
        build_model("ensemble", members=[])


def test_save_load_round_trip(tmp_path):
    ens = EnsembleCorrection(members()).eval()
    path = save_model(ens, {"name": "ensemble", "members": cfgs()}, tmp_path / "e.pt", {"dataset": "x"})
    blob = torch.load(path, weights_only=True)
    assert blob["format"] == "gyrodenoise-model/1" and blob["model"]["name"] == "ensemble"
    assert {k.split(".")[1] for k in blob["state_dict"]} == {"0", "1", "2"}
    assert all(k.startswith("members.") for k in blob["state_dict"])
    loaded, meta = load_model(path)
    assert isinstance(loaded, EnsembleCorrection) and len(loaded) == 3 and meta["dataset"] == "x"
    imu = random_imu(300)
    x = torch.as_tensor(imu, dtype=torch.float32)[None]
    with torch.no_grad():
        for got, ref in zip(loaded.forward_with_spread(x), ens.forward_with_spread(x), strict=True):
            assert torch.equal(got, ref)


# ------------------------------------------------------------------ building from files


def member_file(folder, k: int, model=None, cfg=None, **meta):
    """A member model file (random weights number k) with training metadata."""
    folder.mkdir(parents=True, exist_ok=True)
    m = model if model is not None else random_model(seed=k, **TINY)
    base = {"dataset": "euroc", "rate_hz": 200.0, "val_aoe_deg": 2.0 + k, "test": {"test/aoe_deg": 3.0 + k}}
    return save_model(m, cfg or {"name": "denoiser", **TINY}, folder / "model.pt", {**base, **meta})


def test_a_one_member_ensemble_is_built_with_a_warning_that_it_has_no_spread(tmp_path):
    a = member_file(tmp_path / "a", 0, seed=0)
    out = tmp_path / "one.pt"
    with pytest.warns(ModelQualityWarning, match="an ensemble of one member .* has no spread"):
        assert ensemble_cli.main(["build", str(a), "--out", str(out)]) == 0
    ens, meta = load_model(out)
    assert len(ens) == 1 and meta["n_members"] == 1


def test_build_cli_from_files_and_multirun(tmp_path, capsys):
    a = member_file(tmp_path / "a", 0, seed=0, fold=1)
    b = member_file(tmp_path / "b", 1, model=calibrated_model(1), cfg={"name": "calibrated"}, seed=1, fold=2)
    out = tmp_path / "euroc-ensemble.pt"
    assert ensemble_cli.main(["build", str(a), str(b), "--out", str(out), "--name", "my-ens"]) == 0
    ens, meta = load_model(out)
    assert isinstance(ens, EnsembleCorrection) and len(ens) == 2
    assert meta["name"] == "my-ens" and meta["n_members"] == 2 and meta["rate_hz"] == 200.0
    assert [r["path"] for r in meta["members"]] == [str(a), str(b)]
    assert [r["seed"] for r in meta["members"]] == [0, 1] and [r["fold"] for r in meta["members"]] == [1, 2]
    assert [r["val_aoe_deg"] for r in meta["members"]] == [2.0, 3.0]
    assert [r["test_aoe_deg"] for r in meta["members"]] == [3.0, 4.0]
    assert meta["beats_calibrated"] is None and "ensemble build" in meta["command"]
    imu = random_imu(200)
    ref = (run_model(load_model(a)[0], imu) + run_model(load_model(b)[0], imu)) / 2
    assert torch.allclose(run_model(ens, imu), ref, atol=1e-6)

    # a Hydra multirun folder: numbered runs, seeds in .hydra/config.yaml (not in the metadata)
    sweep = tmp_path / "multirun"
    for job, seed in [(0, 10), (1, 11), (2, 12)]:
        member_file(sweep / str(job), seed)
        (sweep / str(job) / ".hydra").mkdir()
        (sweep / str(job) / ".hydra" / "config.yaml").write_text(f"seed: {seed}\n")
    (sweep / "3" / ".hydra").mkdir(parents=True)  # a job that failed or was stopped: no model.pt
    assert ensemble_cli.main(["build", "--from-multirun", str(sweep)]) == 2
    assert "job(s) 3 have no model.pt" in capsys.readouterr().err and not (sweep / "ensemble.pt").exists()
    assert ensemble_cli.main(["build", "--from-multirun", str(sweep), "--allow-missing"]) == 0
    ens, meta = load_model(sweep / "ensemble.pt")
    assert len(ens) == 3 and [r["seed"] for r in meta["members"]] == [10, 11, 12]
    # an ensemble file among the members contributes its members
    assert ensemble_cli.main(["build", str(sweep / "ensemble.pt"), str(a), "--out", str(tmp_path / "x.pt")]) == 0
    assert len(load_model(tmp_path / "x.pt")[0]) == 4


def test_build_refuses_different_input_conventions(tmp_path, capsys):
    a = member_file(tmp_path / "a", 0)
    b = member_file(tmp_path / "b", 1, rate_hz=100.0)
    c = member_file(tmp_path / "c", 2, dataset="tumvi")
    out = tmp_path / "e.pt"
    assert ensemble_cli.main(["build", str(a), str(b), "--out", str(out)]) == 2
    assert "different IMU rates" in capsys.readouterr().err and not out.exists()
    assert ensemble_cli.main(["build", str(a), str(b), "--out", str(out), "--allow-mixed"]) == 2
    assert ensemble_cli.main(["build", str(a), str(c), "--out", str(out)]) == 2
    assert "different datasets" in capsys.readouterr().err
    assert ensemble_cli.main(["build", str(a), str(c), "--out", str(out), "--allow-mixed"]) == 0
    assert ensemble_cli.main(["build", "--from-multirun", str(tmp_path / "none")]) == 2


def test_scale_cli_calibrates_the_spread_and_keeps_the_mean(tmp_path, capsys):
    files = [member_file(tmp_path / c, k) for k, c in enumerate("abc")]
    raw = tmp_path / "ens.pt"
    assert ensemble_cli.main(["build", *map(str, files), "--out", str(raw)]) == 0
    scaled = tmp_path / "ens-scaled.pt"
    argv = ["scale", str(raw), "--by", "1.6", "--fitted-by", "fold check", "--out", str(scaled)]
    assert ensemble_cli.main(argv) == 0
    ens0, (ens1, meta1) = load_model(raw)[0], load_model(scaled)
    imu = random_imu(400)
    (m0, s0), (m1, s1) = predict_with_spread(ens0, imu), predict_with_spread(ens1, imu)
    assert np.array_equal(m0, m1) and s0.mean() > 1e-4 and np.allclose(s1, 1.6 * s0, rtol=1e-6)
    assert meta1["model"]["spread_scale"] == 1.6 and meta1["spread_scale"]["fitted_by"] == "fold check"
    assert meta1["spread_scale"]["previous"] == 1.0 and meta1["n_members"] == 3  # the rest of the metadata kept
    assert meta1["name"] == "ens (spread x1.6)"  # not "ens": outputs name the model that ran
    named = tmp_path / "named.pt"
    assert ensemble_cli.main(["build", *map(str, files), "--out", str(named), "--name", "mine"]) == 0
    argv = ["scale", str(named), "--by", "2", "--fitted-by", "x", "--out", str(tmp_path / "n2.pt")]
    assert ensemble_cli.main(argv) == 0 and load_model(tmp_path / "n2.pt")[1]["name"] == "mine (spread x2)"
    # a new ensemble built from a scaled one starts again from the raw spread, and says so
    with pytest.warns(UserWarning, match="spread_scale 1.6 .* not carried"):
        assert ensemble_cli.main(["build", str(scaled), "--out", str(tmp_path / "re.pt")]) == 0
    assert load_model(tmp_path / "re.pt")[0].spread_scale == 1.0
    # what has no spread cannot be scaled; a factor must be positive
    assert (
        ensemble_cli.main(["scale", str(files[0]), "--by", "2", "--fitted-by", "x", "--out", str(tmp_path / "s.pt")])
        == 2
    )
    assert "no spread to scale" in capsys.readouterr().err
    assert ensemble_cli.main(["scale", str(raw), "--by", "0", "--fitted-by", "x", "--out", str(tmp_path / "s.pt")]) == 2
    assert "a spread factor from 0.001 to 1000" in capsys.readouterr().err and not (tmp_path / "s.pt").exists()


@pytest.mark.slow
def test_experiment_ensemble_trains_members_and_builds(tmp_path):
    """`-m experiment=ensemble` with 2 seeds on tiny synthetic data ends with <sweep>/ensemble.pt."""
    from _asl import TINY_TRAINING, write_asl_sequence

    root = tmp_path / "asl"
    for i, name in enumerate(["seq_a", "seq_b"]):
        write_asl_sequence(root / name, seconds=6.0, seed=i)
    sweep = tmp_path / "multirun"
    run_train(
        [
            "-m",
            "experiment=ensemble",
            "seed=0,1",
            "dataset=asl_folder",
            f"dataset.root={root}",
            "dataset.train_seqs=[seq_a]",
            "dataset.test_seqs=[seq_b]",
            *TINY_TRAINING,
            f"hydra.sweep.dir={sweep}",
        ],
        cwd=tmp_path,
    )
    ens, meta = load_model(sweep / "ensemble.pt")
    assert len(ens) == 2 and [r["seed"] for r in meta["members"]] == [0, 1]
    ref = meta["spread_reference"]  # taken on the members' training sequence, read through the sweep's dataset
    assert list(ref["per_recording_rad_s"]) == ["seq_a"] and ref["reference_rad_s"] > 0


# ------------------------------------------------------------------ users: streaming, ONNX, correct


@pytest.mark.parametrize("backend", ["numpy", "torch"])
def test_streaming_ensemble_equals_batch(backend):
    ens = EnsembleCorrection(members(), spread_scale=1.5).eval()  # the scale must reach the streamed std too
    imu = random_imu(700)
    mean, std = predict_with_spread(ens, imu)
    sc = StreamingCorrector(ens, backend=backend)
    assert sc.receptive_field == ens.receptive_field
    singles = [sc.push_with_spread(s) for s in imu[:50]]
    m_chunk, s_chunk = sc.push_chunk_with_spread(imu[50:])
    got_m = np.concatenate([np.stack([m for m, _ in singles]), m_chunk])
    got_s = np.concatenate([np.stack([s for _, s in singles]), s_chunk])
    assert np.abs(got_m - mean).max() < STREAM_ATOL and np.abs(got_s - std).max() < STREAM_ATOL
    assert std.mean() > 1e-3  # a spread that is not trivially zero
    sc.reset()
    assert np.abs(sc.push_chunk(imu) - mean).max() < STREAM_ATOL and sc.n_pushed == len(imu)


def test_onnx_ensemble_outputs_mean_and_std(tmp_path):
    pytest.importorskip("onnxscript")
    ort = pytest.importorskip("onnxruntime")
    from gyrodenoise.export import INPUT_NAME, OUTPUT_NAME, STD_NAME, export_onnx, onnx_parity

    ens = EnsembleCorrection(members(), spread_scale=1.5).eval()  # the exported std carries the scale
    path = export_onnx(ens, tmp_path / "e.onnx")
    sess = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    assert [o.name for o in sess.get_outputs()] == [OUTPUT_NAME, STD_NAME]
    for n in (1, 333):
        x = random_imu(n, seed=n)[None].astype(np.float32)
        y_mean, y_std = sess.run(None, {INPUT_NAME: x})
        with torch.no_grad():
            ref_mean, ref_std = ens.forward_with_spread(torch.from_numpy(x))
        assert np.abs(y_mean - ref_mean.numpy()).max() < ONNX_ATOL
        assert np.abs(y_std - ref_std.numpy()).max() < ONNX_ATOL
    assert onnx_parity(ens, path) < ONNX_ATOL


def write_asl_imu(path, imu: np.ndarray, rate: float = 200.0):
    t_ns = 1_600_000_000_000_000_000 + np.round(np.arange(len(imu)) / rate * 1e9).astype(np.int64)
    with open(path, "w") as fh:
        fh.write("#timestamp [ns],w_x,w_y,w_z,a_x,a_y,a_z\n")
        for t, v in zip(t_ns.tolist(), imu.tolist(), strict=True):
            fh.write(f"{t}," + ",".join(repr(x) for x in v) + "\n")
    return path


def smooth_imu(n: int = 1200) -> np.ndarray:
    """A sane recording for the sanity checks: rest then smooth rotation, gravity in the acc."""
    t = np.arange(n) / 200.0
    gyro = (t > 2)[:, None] * 0.5 * np.sin(2 * np.pi * np.array([0.3, 0.5, 0.7]) * t[:, None])
    acc = np.array([0.0, 0.0, 9.80665]) + 0.01 * np.random.default_rng(0).standard_normal((n, 3))
    return np.concatenate([gyro, acc], axis=1)


def test_correct_writes_std_columns(tmp_path, capsys):
    ens = EnsembleCorrection(members()).eval()
    model = save_model(ens, {"name": "ensemble", "members": cfgs()}, tmp_path / "e.pt", {"rate_hz": 200.0})
    imu = smooth_imu()
    f = write_asl_imu(tmp_path / "data.csv", imu)
    for engine in ("batch", "streaming"):
        assert correct_main([str(f), "-m", str(model), "-o", str(tmp_path / engine), "--engine", engine]) == 0
    err = capsys.readouterr().err
    assert "did not beat" not in err
    header = (tmp_path / "batch" / "imu_corrected.csv").read_text().splitlines()[0]
    assert header.endswith(",w_std_x [rad s^-1],w_std_y [rad s^-1],w_std_z [rad s^-1]")
    d = np.loadtxt(tmp_path / "batch" / "imu_corrected.csv", delimiter=",", comments="#")
    s = np.loadtxt(tmp_path / "streaming" / "imu_corrected.csv", delimiter=",", comments="#")
    assert d.shape == (len(imu), 10)
    mean, std = predict_with_spread(ens, imu)
    np.testing.assert_allclose(d[:, 1:4], mean, atol=1e-8)
    np.testing.assert_allclose(d[:, 7:10], std, rtol=1e-5, atol=1e-10)
    assert np.abs(s[:, 1:4] - d[:, 1:4]).max() < STREAM_ATOL and np.abs(s[:, 7:10] - d[:, 7:10]).max() < STREAM_ATOL
    assert len(read_imu(tmp_path / "batch" / "imu_corrected.csv").t_ns) == len(imu)  # still an ASL file
    summary = json.loads((tmp_path / "batch" / "correct_summary.json").read_text())
    assert summary["ensemble_members"] == 3 and summary["mean_std_deg_s"] > 0


# ------------------------------------------------------------------ beats_calibrated warning


def test_model_not_beating_calibrated_warns(tmp_path, capsys):
    meta = {"rate_hz": 200.0, "dataset": "euroc", "beats_calibrated": False}
    meta |= {"val_aoe_deg": 4.0, "calibrated_val_aoe_deg": 3.3}
    bad = save_model(random_model(seed=1, **TINY), {"name": "denoiser", **TINY}, tmp_path / "bad.pt", meta)
    good = save_model(
        random_model(seed=1, **TINY),
        {"name": "denoiser", **TINY},
        tmp_path / "good.pt",
        {**meta, "beats_calibrated": True},
    )
    unknown = save_model(calibrated_model(0), {"name": "calibrated"}, tmp_path / "unknown.pt", {"rate_hz": 200.0})
    msg = not_better_warning(load_model(bad)[1])
    assert "did not beat" in msg and "4.00 deg vs 3.30 deg" in msg
    if "euroc-calibrated" in available_models():
        assert "'euroc-calibrated' instead" in msg
    assert not_better_warning(load_model(good)[1]) is None and not_better_warning(load_model(unknown)[1]) is None
    named = save_model(
        calibrated_model(0), {"name": "calibrated"}, tmp_path / "n.pt", {**meta, "calibrated_model": "runs/cal.pt"}
    )
    assert "'runs/cal.pt' instead" in not_better_warning(load_model(named)[1])
    # a training run records the file name beside model.pt: the advice gives the path where it is
    save_model(calibrated_model(0), {"name": "calibrated"}, tmp_path / "run" / "calibrated.pt", {"rate_hz": 200.0})
    beside = save_model(
        calibrated_model(0),
        {"name": "calibrated"},
        tmp_path / "run" / "model.pt",
        {**meta, "calibrated_model": "calibrated.pt"},
    )
    assert f"{tmp_path / 'run' / 'calibrated.pt'}' instead" in not_better_warning(load_model(beside)[1])
    if {"tumvi", "tumvi-denoiser"} <= set(available_models()):  # TUM-VI's default IS the calibrated model: name it
        assert "the calibrated model 'tumvi' instead" in not_better_warning(load_model("tumvi-denoiser")[1])

    with pytest.warns(ModelQualityWarning, match="did not beat") as caught:  # the Python API warns by itself
        load_model(bad)
    assert len(caught) == 1
    with pytest.warns(ModelQualityWarning, match="did not beat") as caught:  # what evaluate does on loading
        load_checked(str(bad))
    assert len(caught) == 1  # once, not once by load_model and once by evaluate
    with warnings.catch_warnings():
        warnings.simplefilter("error", ModelQualityWarning)
        load_checked(str(good))
        load_model(good)
        load_model(bad, warn=False)

    f = write_asl_imu(tmp_path / "data.csv", smooth_imu(600))
    assert correct_main([str(f), "-m", str(bad), "-o", str(tmp_path / "o")]) == 0
    err = capsys.readouterr().err
    assert "warning: model" in err and "did not beat the 12-parameter calibrated baseline" in err
    assert err.count("did not beat") == 1, err
    assert json.loads((tmp_path / "o" / "correct_summary.json").read_text())["beats_calibrated"] is False
    assert correct_main([str(f), "-m", str(good), "-o", str(tmp_path / "g")]) == 0
    assert "did not beat" not in capsys.readouterr().err
    # --strict: the outputs are written and the exit status tells a script (3), only for a model warning
    assert correct_main([str(f), "-m", str(bad), "-o", str(tmp_path / "s"), "--strict"]) == 3
    assert (tmp_path / "s" / "imu_corrected.csv").is_file() and "exit 3 (--strict)" in capsys.readouterr().err
    assert correct_main([str(f), "-m", str(good), "-o", str(tmp_path / "t"), "--strict"]) == 0


# ------------------------------------------------------------------ uncertainty calibration


def synthetic_errors(sigma_per_window: np.ndarray, window: int, rate: float, seed: int, independent: bool = False):
    """Ground truth, and a gyro whose error has the given std: constant over each window
    (correlated) or white (independent)."""
    rng = np.random.default_rng(seed)
    n = len(sigma_per_window) * window + 1
    dt = np.full(n, 1.0 / rate)
    t = np.arange(n) / rate
    w_true = 0.5 * np.sin(2 * np.pi * np.array([0.1, 0.23, 0.37]) * t[:, None])
    R = integrate_gyro(np.eye(3), w_true, dt)
    sigma = np.repeat(sigma_per_window, window, axis=0)
    sigma = np.concatenate([sigma[:1], sigma])  # sample 0 (unused by integration) like sample 1
    if independent:
        err = sigma * rng.standard_normal((n, 3))
    else:
        z = np.repeat(rng.standard_normal((len(sigma_per_window), 3)), window, axis=0)
        err = sigma * np.concatenate([z[:1], z])
    return w_true + err, sigma, dt, R


@pytest.mark.parametrize("mode", ["correlated", "independent"])
def test_calibration_synthetic(mode):
    rng = np.random.default_rng(0)
    n_windows, rate = 300, 100.0
    sigma_w = np.repeat(10 ** rng.uniform(-4, -1, (n_windows, 1)), 3, axis=1)  # rad/s, 3 decades
    gyro, sigma, dt, R = synthetic_errors(sigma_w, int(rate), rate, seed=1, independent=mode == "independent")

    res = calibration(gyro, sigma, dt, R, window_s=1.0, n_bins=5, mode=mode)
    assert len(res.predicted) == n_windows
    assert res.spearman > 0.8 and res.p_value < 1e-10
    ratios = [row["ratio"] for row in res.table]
    assert all(0.7 < r < 1.4 for r in ratios), ratios  # errors drawn with the given sigma: calibrated

    # the same errors judged with shuffled sigmas: no rank correlation left
    perm = np.random.default_rng(2).permutation(n_windows)
    shuffled = np.concatenate([sigma[:1], np.repeat(sigma_w[perm], int(rate), axis=0)])
    res_shuffled = calibration(gyro, shuffled, dt, R, window_s=1.0, mode=mode)
    assert abs(res_shuffled.spearman) < 0.2

    # a spread 3x too small keeps the ranks (Spearman) but the table shows it: actual / predicted ~ 3
    res_small = calibration(gyro, sigma / 3, dt, R, window_s=1.0, n_bins=5, mode=mode)
    assert res_small.spearman == pytest.approx(res.spearman)
    assert all(2.1 < row["ratio"] < 4.2 for row in res_small.table)


def test_calibration_skips_windows_without_ground_truth():
    sigma_w = np.full((10, 3), 1e-3)
    gyro, sigma, dt, R = synthetic_errors(sigma_w, 100, 100.0, seed=3)
    mask = np.ones(len(gyro), dtype=bool)
    mask[250] = False  # inside window 2
    res = calibration(gyro, sigma, dt, R, gt_mask=mask, window_s=1.0)
    assert len(res.predicted) == 9 and 2 not in res.starts // 100
    assert np.isnan(res.spearman)  # constant sigma: no ranks to correlate
    with pytest.raises(ValueError, match="mode"):
        calibration(gyro, sigma, dt, R, mode="other")


# ------------------------------------------------------------------ calibrated baseline fit


def synthetic_sequence(
    name: str, seconds: float, C: np.ndarray, bias: np.ndarray, seed: int, G: np.ndarray | None = None
) -> Sequence:
    """Ground truth from a smooth rate; the raw gyro is what C_hat w + bias (+ G acc) maps back to it."""
    rng = np.random.default_rng(seed)
    rate = 200.0
    n = int(seconds * rate) + 1
    t = np.arange(n) / rate
    f = rng.uniform(0.1, 0.6, 3)
    w_true = 0.8 * np.sin(2 * np.pi * f * t[:, None] + rng.uniform(0, 6, 3))
    R = integrate_gyro(np.eye(3), w_true, np.full(n, 1 / rate))
    acc = Rotation.from_matrix(R).inv().apply([0, 0, 9.81])
    g_term = 0.0 if G is None else acc @ G.T
    raw = (w_true - bias - g_term) @ np.linalg.inv(C).T + 1e-3 * rng.standard_normal((n, 3))
    return Sequence(name, 0, t, raw, acc, R, np.zeros((n, 3)), np.ones(n, dtype=bool))


def test_fit_calibrated_recovers_c_and_bias_and_flags():
    rng = np.random.default_rng(0)
    C = np.eye(3) + 0.01 * rng.standard_normal((3, 3))
    bias = np.array([0.02, -0.03, 0.07])  # rad/s: a few deg/s, as the ADIS16448
    train = [synthetic_sequence(f"s{i}", 30.0, C, bias, i) for i in range(3)]
    val = [synthetic_sequence("v", 20.0, C, bias, 9)]
    cal = fit_calibrated(train)
    assert isinstance(cal, CalibratedImu) and not cal.training
    np.testing.assert_allclose(cal.bias.detach().numpy(), bias, atol=2e-4)
    np.testing.assert_allclose(cal.C_hat.detach().numpy(), C, atol=2e-3)

    scores = evaluate_on(cal, val)
    raw = build_model("calibrated")  # identity and zero bias: the raw IMU
    assert set(scores) == {"v"} and scores["v"] < 0.1 < evaluate_on(raw, val)["v"]
    flags = safety_meta(raw, cal, val, calibrated_path="cal.pt")
    assert flags["beats_calibrated"] is False and flags["calibrated_model"] == "cal.pt"
    assert flags["calibrated_val_aoe_deg"] == pytest.approx(scores["v"])
    assert safety_meta(cal, raw, val)["beats_calibrated"] is True
    assert safety_meta(cal, raw, [])["beats_calibrated"] is None


def test_fit_calibrated_recovers_g_sensitivity():
    """model.g_sensitivity: w_hat = C_hat w + b + G a; the same L-BFGS fit recovers a G of ~0.5 deg/s/g from motion
    that tilts the body, and the 12-parameter fit cannot take its place."""
    rng = np.random.default_rng(1)
    C = np.eye(3) + 0.01 * rng.standard_normal((3, 3))
    bias = np.array([0.02, -0.03, 0.07])
    G = np.radians(0.5) / 9.81 * rng.standard_normal((3, 3))  # rad/s per m/s^2
    train = [synthetic_sequence(f"s{i}", 30.0, C, bias, i, G) for i in range(3)]
    val = [synthetic_sequence("v", 20.0, C, bias, 9, G)]
    cal_g = fit_calibrated(train, g_sensitivity=True)
    np.testing.assert_allclose(cal_g.G.detach().numpy(), G, atol=0.05 * np.abs(G).max())
    np.testing.assert_allclose(cal_g.bias.detach().numpy(), bias, atol=5e-4)
    assert evaluate_on(cal_g, val)["v"] < 0.5 * evaluate_on(fit_calibrated(train), val)["v"]
    rebuilt = build_model("calibrated", g_sensitivity=True)
    rebuilt.load_state_dict(cal_g.state_dict())
    imu = val[0].imu
    np.testing.assert_allclose(predict_gyro(rebuilt, imu).numpy(), predict_gyro(cal_g, imu).numpy())
    with pytest.raises(ValueError, match="g_sensitivity"):
        build_model("calibrated", scale=1)


def test_real_euroc_slice_ensemble(euroc_root):
    """20 s of V1_01_easy: the shipped EuRoC ensemble, batch vs streaming, and the calibration check runs
    on real ground truth."""
    if not {"euroc", "euroc-calibrated"} <= set(available_models()):
        pytest.skip("shipped EuRoC models absent")
    from gyrodenoise.data.cache import load_sequence

    seq = load_sequence(euroc_root, "V1_01_easy", "state_groundtruth_estimate0/data_recomputed_openvins.csv")
    seq = seq.slice(2000, 6000)
    ens = load_model("euroc")[0]
    assert isinstance(ens, EnsembleCorrection) and len(ens) > 1
    mean, std = predict_with_spread(ens, seq.imu)
    sc = StreamingCorrector(ens)
    m2, s2 = sc.push_chunk_with_spread(seq.imu)
    assert np.abs(m2 - mean).max() < STREAM_ATOL and np.abs(s2 - std).max() < STREAM_ATOL
    res = calibration(mean, std, seq.dt, seq.rot, seq.gt_mask)
    assert len(res.predicted) == 19 and np.isfinite(res.spearman)


@pytest.mark.slow
def test_evaluate_with_an_ensemble(euroc_root, tmp_path):
    """evaluate with an ensemble as the proposed model (the shipped `euroc` is one): Table 1 rows, the
    spread's calibration in results.json and its figure, the +-2 sigma correction figure."""
    if not {"euroc", "euroc-calibrated"} <= set(available_models()):
        pytest.skip("shipped EuRoC models absent")
    from test_evaluate import run_evaluate

    out = tmp_path / "eval"
    summary = run_evaluate(
        "dataset=euroc",
        f"dataset.root={euroc_root}",
        "dataset.test_seqs=[V1_03_difficult]",
        f"out_dir={out}",
    )
    u = summary["uncertainty"]
    assert u["ensemble_members"] == len(load_model("euroc")[0]) and u["pooled"]["windows"] > 50
    assert -1 <= u["pooled"]["spearman"] <= 1 and len(u["pooled"]["table"]) == 10
    a = summary["aoe_deg"]["V1_03_difficult"]
    assert a["proposed"][0] < a["raw IMU"][0]
    for name in ("figures/uncertainty_calibration.png", "figures/correction_V1_03_difficult.png", "results.json"):
        assert (out / name).is_file(), name


def test_ensemble_of_members_that_all_failed_warns_and_duplicates_are_refused(tmp_path):
    """Built from members that all lost to the calibrated baseline, the ensemble warns on loading as they do;
    the same member twice is refused (it would count double and shrink the spread)."""
    meta = {"rate_hz": 200.0, "dataset": "own", "beats_calibrated": False}
    meta |= {"val_aoe_deg": 4.0, "calibrated_val_aoe_deg": 3.3}
    paths = [
        save_model(random_model(seed=s, **TINY), {"name": "denoiser", **TINY}, tmp_path / f"m{s}.pt", meta)
        for s in (1, 2)
    ]
    with pytest.warns(UserWarning, match="did not beat"):
        model, cfg, ens_meta = ensemble_cli.make_ensemble(paths)
    ens = save_model(model, cfg, tmp_path / "ens.pt", ens_meta)
    msg = not_better_warning(load_model(ens)[1])
    assert msg is not None and "none of its 2 members" in msg and "4.00 deg vs 3.30 deg" in msg
    # with the members' own baselines beside them, that is what it names (it named the shipped 'own-calibrated'-like)
    cal = save_model(calibrated_model(0), {"name": "calibrated"}, tmp_path / "calibrated.pt")
    with_cal = [
        save_model(random_model(seed=s, **TINY), {"name": "denoiser", **TINY}, tmp_path / f"c{s}.pt",
                   meta | {"calibrated_model": "calibrated.pt"})
        for s in (3, 4)
    ]  # fmt: skip
    with pytest.warns(UserWarning, match="did not beat"):
        model, cfg, ens_meta = ensemble_cli.make_ensemble(with_cal)
    msg = not_better_warning(load_model(save_model(model, cfg, tmp_path / "ens2.pt", ens_meta))[1])
    assert f"use the calibrated model '{cal}' instead" in msg
    with pytest.raises(ValueError, match="the same member twice"):
        ensemble_cli.make_ensemble([paths[0], paths[0]])
    with pytest.raises(ValueError, match="the same member twice"):  # an ensemble brings its members
        ensemble_cli.make_ensemble([ens, paths[1]])
    # the same weights re-saved with other metadata: another file, the same network (compared bytes passed it)
    resaved = save_model(load_model(paths[0])[0], {"name": "denoiser", **TINY}, tmp_path / "copy.pt", meta | {"x": 1})
    with pytest.raises(ValueError, match=r"the same member twice: .*copy.pt and .*m1.pt \(same weights\)"):
        ensemble_cli.make_ensemble([paths[0], paths[1], resaved])


def test_reference_without_its_data_says_how_to_give_the_folder(tmp_path, capsys):
    argv = ["reference", "euroc", "--out", str(tmp_path / "r.pt"), "dataset=euroc", f"dataset.root={tmp_path / 'no'}"]
    assert ensemble_cli.main(argv) == 2
    err = capsys.readouterr().err
    assert "data folder not found" in err and "dataset.root=FOLDER" in err and "GYRODENOISE_DATA" in err
    assert not (tmp_path / "r.pt").exists()


def test_calibration_of_a_sequence_without_one_whole_window_of_ground_truth():
    """A recording whose ground truth breaks off more often than once a second (occlusions) has no 1-s window to
    score: the calibration is empty (no windows, no table, NaN figures; not a ratio of inf), and pooled with another
    sequence's, and drawn, it works (evaluate with the shipped `euroc` ensemble stopped in numpy's ValueError)."""
    from gyrodenoise import plots
    from gyrodenoise.uncertainty import pooled

    sigma_w = np.full((10, 3), 1e-3)
    gyro, sigma, dt, R = synthetic_errors(sigma_w, 100, 100.0, seed=3)
    mask = np.ones(len(gyro), dtype=bool)
    mask[50::100] = False  # a sample without ground truth inside every window
    empty = calibration(gyro, sigma, dt, R, gt_mask=mask, window_s=1.0)
    s = empty.summary()
    assert s["windows"] == 0 and s["table"] == []
    assert np.isnan(s["spearman"]) and np.isnan(s["rms_ratio"]) and np.isnan(s["rms_actual_deg"])
    whole = calibration(gyro, sigma, dt, R, window_s=1.0, n_bins=5)
    both = pooled([empty, whole], n_bins=5)
    assert both.summary()["windows"] == 10 and len(both.table) == 5
    plots.calibration_figure(pooled([empty]), "no windows")
