"""ONNX / torch.export: the exported graph (normalisation and C_hat inside) equals the PyTorch model."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from _models import random_imu, random_model

from gyrodenoise.export import INPUT_NAME, OUTPUT_NAME, ExportWrapper, export_onnx, export_pt2, main, output_names
from gyrodenoise.models.build import build_model
from gyrodenoise.pretrained import save_model
from gyrodenoise.stateful_graph import StatefulCorrection

TINY = {"channels": (8, 16), "kernel_size": 5, "dilations": (1, 4), "act": "gelu", "dropout": 0.1}
ATOL = 1e-5


@pytest.fixture(scope="module")
def tiny():
    m = random_model(seed=2, **TINY)
    imu = random_imu(400)
    m.set_normalization(imu.mean(0), imu.std(0))  # non-trivial normalisation that must travel along
    return m


def torch_out(model, x: np.ndarray) -> np.ndarray:
    with torch.no_grad():
        return model(torch.as_tensor(x, dtype=torch.float32)).numpy()


def test_onnx_parity_dynamic_length(tiny, tmp_path):
    pytest.importorskip("onnxscript")
    ort = pytest.importorskip("onnxruntime")
    path = export_onnx(tiny, tmp_path / "m.onnx")
    sess = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    for batch, n in [(1, 1), (1, 7), (2, 333), (1, 2500)]:
        x = np.stack([random_imu(n, seed=batch + n + k) for k in range(batch)]).astype(np.float32)
        (y,) = sess.run(None, {INPUT_NAME: x})
        assert y.shape == (batch, n, 3)
        assert np.abs(y - torch_out(tiny, x)).max() < ATOL


def test_onnx_calibrated_model(tmp_path):
    pytest.importorskip("onnxscript")
    ort = pytest.importorskip("onnxruntime")
    m = build_model("calibrated")
    m.bias.data[:] = torch.tensor([0.01, 0.02, -0.03])
    m.C_delta.data.normal_(std=0.01)
    sess = ort.InferenceSession(str(export_onnx(m, tmp_path / "c.onnx")))
    x = random_imu(50)[None].astype(np.float32)
    assert np.abs(sess.run(None, {INPUT_NAME: x})[0] - torch_out(m, x)).max() < 1e-6


def test_torch_export_roundtrip(tiny, tmp_path):
    program = torch.export.load(export_pt2(tiny, tmp_path / "m.pt2")).module()
    for n in (3, 900):
        x = random_imu(n, seed=n)[None].astype(np.float32)
        with torch.no_grad():
            y = program(torch.from_numpy(x)).numpy()
        assert np.abs(y - torch_out(tiny, x)).max() < ATOL


def test_export_leaves_model_untouched(tiny, tmp_path):
    before = {k: v.clone() for k, v in tiny.state_dict().items()}
    tiny.train()
    export_pt2(tiny, tmp_path / "m.pt2")
    assert tiny.training
    tiny.eval()
    assert all(torch.equal(before[k], v) for k, v in tiny.state_dict().items())


def test_cli(tiny, tmp_path, capsys):
    pytest.importorskip("onnxscript")
    pytest.importorskip("onnxruntime")
    model_file = save_model(tiny, {"name": "denoiser", **TINY}, tmp_path / "tiny.pt", {"rate_hz": 200.0})
    assert main([str(model_file), "--onnx", str(tmp_path / "out.onnx"), "--pt2", str(tmp_path / "out.pt2")]) == 0
    out = capsys.readouterr().out
    assert (tmp_path / "out.onnx").is_file() and (tmp_path / "out.pt2").is_file()
    assert "onnxruntime vs PyTorch" in out
    import onnx  # the file says what its input is: units, channel order, rate

    props = {p.key: p.value for p in onnx.load(str(tmp_path / "out.onnx")).metadata_props}
    assert props["gyrodenoise.rate_hz"] == "200" and "gyro x, y, z [rad/s]" in props["gyrodenoise.input"]
    assert props["gyrodenoise.outputs"] == "gyro_corrected (batch, samples, 3) [rad/s]"
    # what onboard use needs and the graph does not say: the history a call must hold, the accelerometer's content
    rf = tiny.receptive_field
    assert (
        props["gyrodenoise.receptive_field_samples"] == str(rf) and f">= {rf} samples" in props["gyrodenoise.start_up"]
    )
    assert "gravity included" in props["gyrodenoise.accelerometer"] and props["gyrodenoise.exported_by"]


def test_a_graph_that_does_not_reproduce_the_model_is_removed(tiny, tmp_path, capsys, monkeypatch):
    pytest.importorskip("onnxscript")
    pytest.importorskip("onnxruntime")
    import gyrodenoise.export as export

    model_file = save_model(tiny, {"name": "denoiser", **TINY}, tmp_path / "tiny.pt", {"rate_hz": 200.0})
    monkeypatch.setattr(export, "onnx_parity", lambda model, path: 1e-2)  # as a graph traced wrong would score
    assert main([str(model_file), "--onnx", str(tmp_path / "out.onnx")]) == 2
    err = capsys.readouterr().err
    assert "does not reproduce the model (max |diff| 1.00e-02 rad/s > 0.0001" in err
    assert not (tmp_path / "out.onnx").exists()


def test_cli_error_is_one_line(tmp_path, capsys):
    # a model that is not there: `error: ...` naming it and status 2, not a traceback
    assert main([str(tmp_path / "missing.pt"), "--onnx", str(tmp_path / "out.onnx")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and "missing.pt" in err and not (tmp_path / "out.onnx").exists()


def test_an_existing_file_of_another_kind_is_not_replaced(tmp_path, capsys):
    notes = tmp_path / "notes.txt"
    notes.write_text("my notes")
    for flag in ("--onnx", "--pt2"):
        assert main(["euroc-calibrated", flag, str(notes), "--no-check"]) == 2
        err = capsys.readouterr().err
        assert f"{flag} {notes}: this file exists and is not a {flag.replace('--', '.')} file" in err
    assert notes.read_text() == "my notes"


def test_an_output_path_of_another_kind_is_refused_before_any_work(tmp_path, capsys):
    """`--onnx x.txt` (or a name without a suffix) wrote an ONNX file under that name without a word; a path that does
    not end in the flag's suffix is refused in one line naming the flag, the path and what to give, before the model
    is loaded (a model that is not there is not reached)."""
    missing = str(tmp_path / "missing.pt")
    for flag, name, fixed in (
        ("--onnx", "x.txt", "x.onnx"),
        ("--onnx", "model", "model.onnx"),
        ("--pt2", "x.onnx", "x.pt2"),
    ):
        target = tmp_path / name
        assert main([missing, flag, str(target), "--no-check"]) == 2
        err = capsys.readouterr().err
        assert err == (
            f"error: {flag} {target}: not a {flag.replace('--', '.')} path, so nothing was written: give a path "
            f"ending in {flag.replace('--', '.')}, e.g. {tmp_path / fixed}\n"
        )
        assert not target.exists()
    # one good target beside a bad one: nothing is written for either
    good = tmp_path / "m.onnx"
    assert main([missing, "--onnx", str(good), "--pt2", str(tmp_path / "m.txt"), "--no-check"]) == 2
    assert "error: --pt2 " in capsys.readouterr().err and not good.exists()


# ---------------------------------------------------------------- the stateful (streaming) step
CHUNKS = (1, 1, 5, 130, 2, 260, 1)  # one-sample calls, shorter and longer than the receptive field (17)


def _stream(run, x: np.ndarray, n_outputs: int) -> list[np.ndarray]:
    """Feed x (B, N, 6) through `run(chunk, state, reset) -> (*outputs, state)` in CHUNKS; outputs concatenated."""
    outs: list[list[np.ndarray]] = [[] for _ in range(n_outputs)]
    state, start = None, 0
    for size in CHUNKS:
        *ys, state = run(x[:, start : start + size], state, np.full(len(x), start == 0))
        for o, y in zip(outs, ys, strict=True):
            o.append(np.asarray(y))
        start += size
    assert start == x.shape[1]
    return [np.concatenate(o, 1) for o in outs]


def _batch_outputs(model, x: np.ndarray) -> list[np.ndarray]:
    with torch.no_grad():
        y = ExportWrapper(model)(torch.as_tensor(x, dtype=torch.float32))
    return [t.numpy() for t in (y if isinstance(y, tuple) else (y,))]


def _ensemble():
    from gyrodenoise.models.ensemble import EnsembleCorrection

    cal = build_model("calibrated")
    cal.bias.data[:] = torch.tensor([0.01, 0.02, -0.03])
    big = random_model(seed=5, channels=(4, 8, 8), kernel_size=3, dilations=(1, 2, 8))
    return EnsembleCorrection([random_model(seed=3, **TINY), big, cal], spread_scale=1.5).eval()


@pytest.mark.parametrize("which", ["single", "ensemble"])
def test_stateful_step_streams_like_the_batch_model(tiny, which):
    model = tiny if which == "single" else _ensemble()
    step = StatefulCorrection(model)
    x = np.stack([random_imu(sum(CHUNKS), seed=s) for s in (7, 8)]).astype(np.float32)  # two streams side by side

    def run(chunk, state, reset):
        state = step.initial_state(len(chunk)) if state is None else state
        with torch.no_grad():
            return step(torch.from_numpy(chunk), state, torch.from_numpy(reset))

    ref = _batch_outputs(model, x)
    got = _stream(run, x, len(ref))
    assert max(np.abs(g - r).max() for g, r in zip(got, ref, strict=True)) < ATOL
    # reset=True forgets the state passed in: a new stream's first call equals the batch model on it alone
    with torch.no_grad():
        *y, _ = step(torch.from_numpy(x[:, 100:160]), torch.randn(2, step.state_size), torch.tensor([True, True]))
    assert np.abs(y[0].numpy() - _batch_outputs(model, x[:, 100:160])[0]).max() < ATOL


def test_onnx_stateful_export_streams_in_chunks(tmp_path):
    pytest.importorskip("onnxscript")
    ort = pytest.importorskip("onnxruntime")
    import onnx

    model = _ensemble()
    path = export_onnx(model, tmp_path / "s.onnx", stateful=True)
    sess = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    size = StatefulCorrection(model).state_size
    assert [i.name for i in sess.get_inputs()] == ["imu", "state", "reset"]
    assert [o.name for o in sess.get_outputs()] == ["gyro_corrected", "gyro_std", "state_out"]
    x = np.stack([random_imu(sum(CHUNKS), seed=s) for s in (9, 10)]).astype(np.float32)

    def run(chunk, state, reset):
        state = np.zeros((len(chunk), size), np.float32) if state is None else state
        return sess.run(None, {"imu": chunk, "state": state, "reset": reset})

    ref = _batch_outputs(model, x)
    got = _stream(run, x, 2)
    assert max(np.abs(g - r).max() for g, r in zip(got, ref, strict=True)) < ATOL
    props = {p.key: p.value for p in onnx.load(str(path)).metadata_props}
    assert f"state (batch, {size})" in props["gyrodenoise.inputs"] and "state_out" in props["gyrodenoise.outputs"]


def test_stateful_export_of_a_model_without_state_is_refused(tmp_path, capsys):
    pytest.importorskip("onnxscript")
    model_file = save_model(build_model("calibrated"), {"name": "calibrated"}, tmp_path / "cal.pt", {})
    assert main([str(model_file), "--onnx", str(tmp_path / "c.onnx"), "--stateful"]) == 2
    assert "keeps no state" in capsys.readouterr().err and not (tmp_path / "c.onnx").exists()


def test_stateful_torch_export_streams_in_chunks(tiny, tmp_path):
    program = torch.export.load(export_pt2(tiny, tmp_path / "s.pt2", stateful=True)).module()
    x = random_imu(sum(CHUNKS), seed=11)[None].astype(np.float32)

    def run(chunk, state, reset):
        state = torch.zeros(1, StatefulCorrection(tiny).state_size) if state is None else state
        with torch.no_grad():
            return program(torch.from_numpy(chunk), state, torch.from_numpy(reset))

    (got,) = _stream(run, x, 1)
    assert np.abs(got - _batch_outputs(tiny, x)[0]).max() < ATOL
    # called as a user would, outside no_grad: state_out carries no autograd graph that the next call would extend
    y, state = program(
        torch.from_numpy(x[:, :5]), torch.zeros(1, StatefulCorrection(tiny).state_size), torch.tensor([True])
    )
    assert y.grad_fn is None and state.grad_fn is None


def test_a_one_member_ensemble_exports_its_member_without_a_std(tiny, tmp_path):
    """One member measures no spread: the ONNX graph (batch and stateful) has no gyro_std output (it output zeros,
    which read as certainty), and its gyro is the member's."""
    pytest.importorskip("onnxscript")
    ort = pytest.importorskip("onnxruntime")
    from gyrodenoise.models.ensemble import EnsembleCorrection

    ens = EnsembleCorrection([tiny]).eval()
    assert output_names(ens) == [OUTPUT_NAME]
    x = random_imu(300, seed=3).astype(np.float32)[None]
    sess = ort.InferenceSession(str(export_onnx(ens, tmp_path / "m.onnx")), providers=["CPUExecutionProvider"])
    assert [o.name for o in sess.get_outputs()] == [OUTPUT_NAME]
    assert np.abs(sess.run(None, {INPUT_NAME: x})[0] - torch_out(tiny, x)).max() < ATOL
    step = StatefulCorrection(ens)
    with torch.no_grad():
        outs = step(torch.from_numpy(x), step.initial_state(1), torch.tensor([True]))
    assert len(outs) == 2 and np.abs(outs[0].numpy() - torch_out(tiny, x)).max() < ATOL
