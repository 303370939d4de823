"""A user's own network (model=custom): trained, saved, loaded and evaluated by the framework's tools, and refused
clearly where a tool cannot reproduce it (streaming, stateful export) or where it breaks the contract."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import torch
from test_train import tiny_dataset
from torch import nn

from gyrodenoise.config import compose_config
from gyrodenoise.models import DilatedCNNDenoiser, GyroCorrection, build_model
from gyrodenoise.models.build import causality_leak
from gyrodenoise.pretrained import ModelFileError, ModelQualityWarning, load_model
from gyrodenoise.streaming import StreamingCorrector
from gyrodenoise.train import train


class PastMean(GyroCorrection):
    """Causal: a linear map of the mean IMU over the last `k` samples."""

    def __init__(self, k: int = 8) -> None:
        super().__init__()
        self.k = k
        self.lin = nn.Linear(6, 3)
        self.receptive_field = k

    def correction(self, imu: torch.Tensor) -> torch.Tensor:
        x = (imu - self.mean) / self.std
        x = nn.functional.pad(x.transpose(1, 2), (self.k - 1, 0), mode="replicate")
        return 0.01 * self.lin(nn.functional.avg_pool1d(x, self.k, stride=1).transpose(1, 2))


class CentredMean(PastMean):
    """Not causal: the same mean over a window centred on the sample."""

    def correction(self, imu: torch.Tensor) -> torch.Tensor:
        x = (imu - self.mean) / self.std
        x = nn.functional.pad(x.transpose(1, 2), (self.k // 2, self.k - 1 - self.k // 2), mode="replicate")
        return 0.01 * self.lin(nn.functional.avg_pool1d(x, self.k, stride=1).transpose(1, 2))


class NeedsK(PastMean):
    def __init__(self, k: int, hidden: int = 8) -> None:
        super().__init__(k)
        self.receptive_field = np.int64(k)  # a numpy integer is an integer


class NoReceptiveField(GyroCorrection):
    def correction(self, imu: torch.Tensor) -> torch.Tensor:
        return torch.zeros(*imu.shape[:-1], 3)


class Squashed(DilatedCNNDenoiser):
    """A subclass of the built-in network whose correction is another function."""

    def correction(self, imu: torch.Tensor) -> torch.Tensor:
        return torch.tanh(super().correction(imu))


def custom_config(root, out, target: str, *extra: str):
    return compose_config(
        "train",
        [
            *tiny_dataset(root),
            "model=custom",
            f"model._target_={target}",
            "trainer.max_epochs=2",
            "trainer.accelerator=cpu",
            "optim.scheduler.T_0=2",
            "logger=none",
            f"paths.output_dir={out}",
            *extra,
        ],
    )


def test_a_custom_model_trains_loads_and_is_refused_by_streaming(tiny_asl_root, tmp_path):
    summary = train(custom_config(tiny_asl_root, tmp_path / "run", f"{__name__}.PastMean", "+model.k=5"))
    assert summary["causality_leak"] == 0.0
    model, meta = load_model(tmp_path / "run" / "model.pt")
    assert isinstance(model, PastMean) and model.k == 5 and meta["causal"] is True
    assert meta["model"]["_target_"] == f"{__name__}.PastMean"
    with pytest.raises(ValueError, match="PastMean\\) has no streaming form"):
        StreamingCorrector(model)


def test_a_model_that_reads_the_future_is_named_so(tiny_asl_root, tmp_path, capsys):
    summary = train(custom_config(tiny_asl_root, tmp_path / "run", f"{__name__}.CentredMean", "+model.k=9"))
    assert summary["causality_leak"] > 1e-3
    assert "warning: the model is not causal" in capsys.readouterr().out
    with pytest.warns(ModelQualityWarning, match="is not causal: .* it cannot run onboard"):  # said on every load
        assert load_model(tmp_path / "run" / "model.pt")[1]["causal"] is False


class FutureOne(PastMean):
    """Not causal by one sample: output n is the causal output at n + 1."""

    def correction(self, imu: torch.Tensor) -> torch.Tensor:
        c = super().correction(imu)
        return torch.cat([c[:, 1:], c[:, -1:]], 1)


class GlobalPool(PastMean):
    """Not causal: one correction from the mean over the whole window."""

    def correction(self, imu: torch.Tensor) -> torch.Tensor:
        x = (imu - self.mean) / self.std
        return 0.01 * self.lin(x.mean(1, keepdim=True)).expand(-1, imu.shape[1], -1)


class WindowNorm(PastMean):
    """Not causal: each window normalised by its own mean and std over time."""

    def correction(self, imu: torch.Tensor) -> torch.Tensor:
        return 0.01 * self.lin((imu - imu.mean(1, keepdim=True)) / imu.std(1, keepdim=True))


@pytest.mark.parametrize("leaky", [CentredMean, FutureOne, GlobalPool, WindowNorm])
def test_networks_that_read_the_future_in_any_way_are_found(leaky):
    """A redraw of the later samples from the same distribution left window statistics where they were: pooling and
    normalising over time, and a one-sample look-ahead, scored under 1e-5 and were stamped causal."""
    torch.manual_seed(0)
    assert causality_leak(leaky(k=9)) > 0.1
    assert causality_leak(PastMean(k=9)) == 0.0


def test_causality_leak_is_zero_for_the_built_in_network():
    torch.manual_seed(0)
    net = build_model("denoiser", channels=[4, 8], dilations=[1, 2])
    nn.init.normal_(net.net[-1].weight)
    assert causality_leak(net) == 0.0


def test_the_contract_is_checked_with_a_message_that_says_it():
    with pytest.raises(ValueError, match="receptive_field=None; set it in __init__"):
        build_model("custom", _target_=f"{__name__}.NoReceptiveField")
    with pytest.raises(ValueError, match="not a GyroCorrection subclass"):
        build_model("custom", _target_="torch.nn.Linear")
    with pytest.raises(ValueError, match="cannot import it .*PYTHONPATH"):
        build_model("custom", _target_="no_such_module_here.Net")
    with pytest.raises(ValueError, match="model.kk is not a parameter of the custom model .*it takes k"):
        build_model("custom", _target_=f"{__name__}.PastMean", kk=3)
    with pytest.raises(ValueError, match="needs name: custom"):
        build_model("denoiser", _target_=f"{__name__}.PastMean")
    with pytest.raises(ValueError, match=r"NeedsK\) needs model.k \(required: k\): add \+model.k="):
        build_model("custom", _target_=f"{__name__}.NeedsK", hidden=4)
    with pytest.raises(ValueError, match="give the class with its module, e.g. mynets.PastMean"):
        build_model("custom", _target_="PastMean")
    assert build_model("custom", _target_=f"{__name__}.NeedsK", k=3).receptive_field == 3


def test_an_ensemble_with_a_custom_member_names_the_member():
    from gyrodenoise.models import EnsembleCorrection

    ens = EnsembleCorrection([build_model("denoiser", channels=[4, 8], dilations=[1, 2]), PastMean(3)])
    with pytest.raises(ValueError, match=r"member 1 \(.*PastMean\) has no streaming form"):
        StreamingCorrector(ens)


def test_a_model_file_whose_class_cannot_be_imported_names_the_file(tmp_path):
    from gyrodenoise.pretrained import save_model

    path = save_model(PastMean(3), {"name": "custom", "_target_": f"{__name__}.PastMean", "k": 3}, tmp_path / "m.pt")
    blob = torch.load(path, weights_only=True)
    blob["model"]["_target_"] = "gone_module.PastMean"
    torch.save(blob, path)
    with pytest.raises(ModelFileError, match="m.pt: this gyrodenoise cannot build the model it holds: .*gone_module"):
        load_model(path)


def test_a_subclass_of_the_built_in_network_is_not_streamed_as_its_parent():
    with pytest.raises(ValueError, match="Squashed\\) has no streaming form"):
        StreamingCorrector(Squashed(channels=(4, 8), dilations=(1, 2)))


def test_bad_shapes_and_flags_of_the_built_in_network_are_named():
    with pytest.raises(ValueError, match=r"model.dilations=\[1, 0\]: give positive integers"):
        build_model("denoiser", channels=[4, 8], dilations=[1, 0])
    with pytest.raises(ValueError, match="model.batch_norm='no'; give true or false"):
        build_model("denoiser", batch_norm="no")
    with pytest.raises(ValueError, match="model.foo is not a parameter of the denoiser model"):
        build_model("denoiser", foo=1)


class ChannelsFirst(PastMean):
    def correction(self, imu: torch.Tensor) -> torch.Tensor:
        return super().correction(imu).transpose(1, 2)


class OneAxis(PastMean):
    def correction(self, imu: torch.Tensor) -> torch.Tensor:
        return super().correction(imu)[..., :1]


class TupleOut(PastMean):
    def correction(self, imu: torch.Tensor) -> tuple:
        return super().correction(imu), None


@pytest.mark.parametrize(
    ("cls", "said"), [(ChannelsFirst, r"\(2, 3, 37\)"), (OneAxis, r"\(2, 37, 1\)"), (TupleOut, "tuple")]
)
def test_a_correction_of_another_shape_is_refused_before_training(cls, said):
    """(B, 3, N) and a tuple failed in the first training step with a traceback; (B, N, 1) was broadcast silently."""
    with pytest.raises(ValueError, match=rf"correction\(\) of raw IMU \(2, 37, 6\) returned {said}, not \(2, 37, 3\)"):
        build_model("custom", _target_=f"{__name__}.{cls.__name__}", k=4)


def test_a_model_whose_module_changed_since_training_is_said_so(tmp_path):
    """model.pt records the import path and the arguments given, not the class's code: an edited module loaded
    silently as another model. The module's sha256 goes with the file; a mismatch warns, and weights that no longer
    fit the class name the class instead of blaming this version of gyrodenoise."""
    from gyrodenoise.pretrained import save_model

    cfg = {"name": "custom", "_target_": f"{__name__}.PastMean", "k": 5}
    path = save_model(PastMean(k=5), cfg, tmp_path / "model.pt")
    blob = torch.load(path, weights_only=True)
    assert blob["meta"]["custom_source"]["module"] == __name__
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        load_model(path)  # the module as trained: no warning
    blob["meta"]["custom_source"]["sha256"] = "0" * 64  # as if the module had been edited since
    torch.save(blob, path)
    with pytest.warns(ModelQualityWarning, match="is not the one this model was trained with"):
        load_model(path)
    blob["state_dict"]["lin.weight"] = torch.zeros(3, 7)  # a layer of another shape: the class changed
    torch.save(blob, path)
    with pytest.raises(ModelFileError, match="the weights do not fit the class .*PastMean as it is now"):
        load_model(path)


class LengthLoop(PastMean):
    """A Python loop over the samples: torch.export specialises the length."""

    def correction(self, imu: torch.Tensor) -> torch.Tensor:
        out = super().correction(imu)
        return torch.stack([out[:, k] for k in range(imu.shape[1])], 1)


def test_a_network_that_cannot_export_at_any_length_is_said_in_one_line(tmp_path, capsys):
    from gyrodenoise.export import main
    from gyrodenoise.pretrained import save_model

    path = save_model(
        LengthLoop(k=4), {"name": "custom", "_target_": f"{__name__}.LengthLoop", "k": 4}, tmp_path / "m.pt"
    )
    assert main([str(path), "--pt2", str(tmp_path / "m.pt2")]) == 2
    err = capsys.readouterr().err
    assert "LengthLoop) could not be exported with a dynamic length" in err and "Traceback" not in err


def test_a_dependency_missing_from_the_users_module_is_named_as_such(tmp_path, monkeypatch):
    """The module was found; what it imports was not: 'put the module on PYTHONPATH' would send the user astray."""
    (tmp_path / "net_with_dep.py").write_text("import a_package_that_is_not_installed\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    with pytest.raises(
        ValueError, match="its module net_with_dep imports a_package_that_is_not_installed, which is not"
    ):
        build_model("custom", _target_="net_with_dep.Net")
    with pytest.raises(ValueError, match="cannot import it .* on PYTHONPATH"):
        build_model("custom", _target_="no_such_module_here.Net")


def test_a_users_network_exported_to_onnx_is_not_described_as_the_built_in_one():
    from gyrodenoise.export import onnx_metadata

    said = onnx_metadata(PastMean(k=4))["gyrodenoise.start_up"]
    assert "PastMean) is a user's network" in said and "pads its start" not in said
    assert (
        "pads its start" in onnx_metadata(build_model("denoiser", channels=[4], dilations=[1]))["gyrodenoise.start_up"]
    )
