"""dataset=asl_folder: train on any folder of ASL sequences with ground truth, split in the config."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from _asl import run_train
from omegaconf.errors import MissingMandatoryValue
from scipy.spatial.transform import Rotation

from gyrodenoise.config import compose_config
from gyrodenoise.pretrained import load_model
from gyrodenoise.so3 import integrate_gyro

RATE = 200.0


def make_sequence(mav0: Path, seconds: float, seed: int, occlusions: tuple[tuple[float, float], ...] = ()) -> None:
    """Smooth rotation; IMU = truth + bias + noise; ground truth in mocap0 at 100 Hz (another rate), none inside
    the `occlusions` (start, end) in seconds."""
    rng = np.random.default_rng(seed)
    n = int(seconds * RATE) + 1
    t = np.arange(n) / RATE
    w = 0.5 * np.sin(2 * np.pi * rng.uniform(0.2, 0.7, 3) * t[:, None] + rng.uniform(0, 3, 3))
    R = integrate_gyro(np.eye(3), w, np.full(n, 1 / RATE))
    acc = np.einsum("nji,j->ni", R, [0.0, 0.0, 9.81]) + rng.normal(0, 0.02, (n, 3))
    gyro = w + [0.01, -0.02, 0.005] + rng.normal(0, 1e-3, (n, 3))
    t_ns = 1_500_000_000_000_000_000 + np.round(t * 1e9).astype(np.int64)
    (mav0 / "imu0").mkdir(parents=True)
    (mav0 / "mocap0").mkdir()
    imu = np.column_stack([gyro, acc])
    with open(mav0 / "imu0" / "data.csv", "w") as fh:
        fh.write("#timestamp [ns],w_x,w_y,w_z,a_x,a_y,a_z\n")
        fh.writelines(f"{s}," + ",".join(f"{v:.9f}" for v in row) + "\n" for s, row in zip(t_ns, imu, strict=True))
    q = Rotation.from_matrix(R[::2]).as_quat()[:, [3, 0, 1, 2]]  # ASL order w, x, y, z
    gt = np.column_stack([np.zeros((len(q), 3)), q])
    with open(mav0 / "mocap0" / "data.csv", "w") as fh:
        fh.write("#timestamp [ns],p_x,p_y,p_z,q_w,q_x,q_y,q_z\n")
        seen = ~np.any([(t[::2] > a) & (t[::2] < b) for a, b in occlusions], axis=0) if occlusions else t[::2] >= 0
        fh.writelines(
            f"{s}," + ",".join(f"{v:.9f}" for v in row) + "\n" for s, row in zip(t_ns[::2][seen], gt[seen], strict=True)
        )


@pytest.fixture(scope="module")
def asl_root(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("my_imu")
    for i, name in enumerate(["walk_1", "walk_2", "walk_3"]):
        make_sequence(root / name / "mav0", seconds=7.0, seed=i)
    return root


def test_config_requires_root_and_split():
    cfg = compose_config("train", ["dataset=asl_folder"])
    with pytest.raises(MissingMandatoryValue):
        _ = cfg.dataset.root
    with pytest.raises(MissingMandatoryValue):
        _ = cfg.dataset.train_seqs


def test_train_two_epochs(asl_root, tmp_path):
    run_dir = tmp_path / "run"
    args = [
        "dataset=asl_folder",
        f"dataset.root={asl_root}",
        "dataset.name=my_imu",
        "dataset.train_seqs=[walk_1,walk_2]",
        "dataset.val_seqs=[walk_1]",
        "dataset.test_seqs=[walk_3]",
        "dataset.train_duration_s=5",
        "dataset.window=256",
        "model.channels=[4,8]",
        "model.dilations=[1,2]",
        "trainer.max_epochs=2",
        "trainer.check_val_every_n_epoch=1",
        "trainer.accelerator=cpu",
        "logger=none",
        f"hydra.run.dir={run_dir}",
    ]
    proc = run_train(args, cwd=tmp_path, timeout=300)
    # what the run printed is also in its folder (Hydra's log file stayed empty before), table included
    log = (run_dir / "train.log").read_text()
    assert "test sequences (my_imu" in proc.stdout and "test sequences (my_imu" in log and "| walk_3 |" in log
    assert "calibrated AOE 3D" in log  # the baseline fitted on the same data, beside the model
    for text in (log, proc.stdout + proc.stderr):  # each Lightning line once, in the log and on the console
        assert text.count("Seed set to") == 1 and text.count("`Trainer.fit` stopped") == 1, text
    summary = json.loads((run_dir / "summary.json").read_text())
    assert summary["command"].startswith("python -m gyrodenoise.train dataset=asl_folder ")
    model, meta = load_model(run_dir / "model.pt")
    assert meta["dataset"] == "my_imu" and meta["train_seqs"] == ["walk_1", "walk_2"]
    assert abs(meta["rate_hz"] - RATE) < 1e-6
    assert model.receptive_field == 1 + 6 * 3


def test_validation_split(asl_root):
    """A validation sequence that is also trained on validates after train_duration_s; one that is not
    validates whole; train_duration_s None trains on whole sequences."""
    from gyrodenoise.data.datamodule import ImuDataModule

    def parts(**kw):
        dm = ImuDataModule(name="my_imu", root=str(asl_root), test_seqs=[], window=256, **kw)
        dm.setup("fit")
        return [len(s.t) for s in dm.train_part], [(s.name, len(s.t)) for s in dm.val_part]

    n = int(7.0 * RATE) + 1
    train, val = parts(train_seqs=["walk_1"], val_seqs=["walk_1", "walk_2"], train_duration_s=5.0)
    assert train == [int(5.0 * RATE) + 1]
    assert val == [("walk_1[5s:]", n - int(5.0 * RATE)), ("walk_2", n)]
    # where each validation part starts in its sequence (evaluate's check for scoring on training data)
    dm = ImuDataModule(name="my_imu", root=str(asl_root), test_seqs=[], window=256, train_seqs=["walk_1"],
                       val_seqs=["walk_1", "walk_2"], train_duration_s=5.0)  # fmt: skip
    dm.setup("fit")
    assert [dm.origin(s) for s in dm.val_part] == [("walk_1", 5.0), ("walk_2", 0.0)]
    train, val = parts(train_seqs=["walk_1", "walk_2"], val_seqs=["walk_3"], train_duration_s=None)
    assert train == [n, n] and val == [("walk_3", n)]
    with pytest.raises(ValueError, match="nothing of it is left"):  # named for validation, but all trained on
        parts(train_seqs=["walk_1"], val_seqs=["walk_1"], train_duration_s=None)
    # whole training sequences and no validation sequence named: nothing to validate on (select=last needs none)
    train, val = parts(train_seqs=["walk_1"], val_seqs=None, train_duration_s=None)
    assert train == [n] and val == []


def test_scored_parts_start_on_measured_ground_truth(tmp_path):
    """A sequence or validation part that would start inside an occlusion starts at the first sample with ground
    truth: estimates are aligned on their first orientation, and inside a gap that one is SLERP across it."""
    from gyrodenoise.data.datamodule import ImuDataModule
    from gyrodenoise.evaluate import estimate

    make_sequence(tmp_path / "occluded" / "mav0", seconds=7.0, seed=5, occlusions=((0.005, 0.4), (4.9, 5.5)))
    dm = ImuDataModule(name="my_imu", root=str(tmp_path), test_seqs=["occluded"], window=256, cache_dir="",
                       train_seqs=["occluded"], val_seqs=["occluded"], train_duration_s=5.0)  # fmt: skip
    dm.setup()
    (whole,), (train,), (val,) = dm.test_part, dm.train_part, dm.val_part
    for part, gap_end in ((whole, 0.4), (train, 0.4), (val, 5.5)):
        assert part.gt_mask[0] and part.t[0] >= gap_end - 0.01 and part.t[0] < gap_end + 0.02, part.name
        assert np.allclose(estimate(part, part.gyro)[0], part.rot[0])
    assert val.name == "occluded[5s:]" and dm.origin(val) == ("occluded", 5.0)


def test_missing_sequences_fail_before_training(asl_root):
    """A run whose test sequences are not in the folder (TUM-VI's withheld rooms) stops before training, and
    says test=false is the way to train without them; a missing training sequence gets no such hint."""
    from gyrodenoise.data.datamodule import ImuDataModule

    def dm(train, test):
        return ImuDataModule(name="my_imu", root=str(asl_root), train_seqs=train, test_seqs=test, window=256)

    with pytest.raises(FileNotFoundError, match=r"not found: room_2, room_4 .*pass test=false"):
        dm(["walk_1"], ["walk_2", "room_2", "room_4"]).check_sequences(test=True)
    dm(["walk_1"], ["room_2"]).check_sequences(test=False)
    with pytest.raises(FileNotFoundError, match=r"not found: walk_9 \(ASL layout") as err:
        dm(["walk_1", "walk_9"], ["room_2"]).check_sequences(test=False)
    assert "test=false" not in str(err.value)
    # no data folder at all: say so (and the environment variable), not "train without the test sequences"
    nowhere = ImuDataModule(name="my_imu", root=str(asl_root / "nowhere"), train_seqs=["walk_1"],
                            test_seqs=["room_2"], window=256)  # fmt: skip
    with pytest.raises(FileNotFoundError, match=r"nowhere: data folder not found.*GYRODENOISE_DATA") as err:
        nowhere.check_sequences(train=False, test=True, test_hint="pass test=false")
    assert "test=false" not in str(err.value) and "gyrodenoise.data.fetch" not in str(err.value)
    # ... and for a dataset the project can download, the command that downloads it
    euroc = ImuDataModule(name="euroc", root=str(asl_root / "nowhere"), train_seqs=["MH_01_easy"], test_seqs=[],
                          window=256)  # fmt: skip
    with pytest.raises(FileNotFoundError, match=r"python -m gyrodenoise.data.fetch euroc --dest \S*nowhere$"):
        euroc.check_sequences(test=False)
    # a typo of a folder that is there: that folder, not a download into the typo (a fresh-user audit's 'eurocc')
    (asl_root / "euroc_x").mkdir()
    typo = ImuDataModule(name="euroc", root=str(asl_root / "euroc_xx"), train_seqs=["MH_01_easy"], test_seqs=[],
                         window=256)  # fmt: skip
    with pytest.raises(FileNotFoundError, match=r"euroc_xx: data folder not found; did you mean \S*euroc_x\?") as err:
        typo.check_sequences(test=False)
    assert "fetch" not in str(err.value)
    # the dataset's folder named twice (GYRODENOISE_DATA set to .../euroc, read as .../euroc/euroc): no download
    twice = ImuDataModule(name="my_imu", root=str(asl_root / "my_imu"), train_seqs=["walk_1"], test_seqs=[], window=256)
    with pytest.raises(FileNotFoundError, match=rf"but {asl_root} holds walk_1: set dataset.root={asl_root}, or"):
        twice.check_sequences(test=False)
    # a root one level too high (the folder that holds the dataset's folder): the folder to give is named
    too_high = ImuDataModule(name="my_imu", root=str(asl_root.parent), train_seqs=["walk_1"], test_seqs=[], window=256)
    one_down = rf"walk_1 is one level further down: give {asl_root} as dataset.root\.$"
    with pytest.raises(FileNotFoundError, match=one_down):
        too_high.check_sequences(test=False)


def test_an_empty_training_list_is_one_line_before_any_data_are_read(asl_root):
    """dataset.train_seqs=[] trained nothing and stopped in Lightning's setup with numpy's 'need at least one array to
    concatenate'; evaluate's test split (train_seqs [] for asl_folder) reads no training sequence and is not refused."""
    from gyrodenoise.cli_errors import ConfigError
    from gyrodenoise.data.datamodule import ImuDataModule

    dm = ImuDataModule(name="my_imu", root=str(asl_root), train_seqs=[], test_seqs=["walk_1"], window=256)
    with pytest.raises(ConfigError, match=r"dataset.train_seqs is empty: name the training sequences"):
        dm.check_sequences(test=False)
    dm.check_sequences(train=False, test=True)


def test_fit_calibrated_alone(asl_root, tmp_path):
    """python -m gyrodenoise.fit_calibrated: the safety net's L-BFGS fit as a model file; it learns the
    synthetic gyro bias, so it beats the raw IMU on a sequence it did not see, and its file reproduces it."""
    from gyrodenoise.baseline import evaluate_on
    from gyrodenoise.fit_calibrated import fit

    overrides = [
        "dataset=asl_folder", f"dataset.root={asl_root}", "dataset.name=my_imu", "dataset.train_seqs=[walk_1,walk_2]",
        "dataset.val_seqs=[walk_3]", "dataset.test_seqs=[walk_3]", "dataset.train_duration_s=null",
        f"paths.output_dir={tmp_path}",
    ]  # fmt: skip
    summary = fit(compose_config("fit_calibrated", overrides))
    model, meta = load_model(tmp_path / "model.pt")
    assert meta["train_seqs"] == ["walk_1", "walk_2"] and meta["train_duration_s"] is None
    assert meta["val_aoe_deg"] == pytest.approx(summary["aoe_deg"]["val"])
    assert summary["aoe_deg"]["test"] == pytest.approx(summary["aoe_deg"]["val"])  # the same sequence
    from gyrodenoise.data.cache import load_sequence

    seq = load_sequence(str(asl_root), "walk_3", None, 3.0, None)
    assert evaluate_on(model, [seq])["walk_3"] == pytest.approx(summary["aoe_deg"]["val"], rel=1e-5)
    raw = evaluate_on(None, [seq])["walk_3"]
    assert summary["aoe_deg"]["val"] < 0.2 * raw

    # model.g_sensitivity=true: the 21-parameter form is fitted and saved as such
    fit(compose_config("fit_calibrated", [*overrides, "model.g_sensitivity=true"]))
    model_g, _ = load_model(tmp_path / "model.pt")
    assert model_g.G is not None and model.G is None


def test_fit_calibrated_runs_with_the_threads_it_is_given(asl_root, tmp_path, monkeypatch):
    """threads=N (and SLURM's cpus-per-task through it) was ignored by fit_calibrated: its L-BFGS fit ran on torch's
    default, every core of a shared node; it is applied for the fit and put back after, as train and evaluate do."""
    import torch

    from gyrodenoise import fit_calibrated as command

    seen = []

    def fit_calibrated(*args, **kwargs):
        seen.append(torch.get_num_threads())
        raise KeyboardInterrupt  # the fit itself is not what is tested

    monkeypatch.setattr(command, "fit_calibrated", fit_calibrated)
    before = torch.get_num_threads()
    wanted = 3 if before != 3 else 2
    overrides = [
        "dataset=asl_folder", f"dataset.root={asl_root}", "dataset.name=my_imu", "dataset.train_seqs=[walk_1]",
        "dataset.test_seqs=[]", "test=false", f"threads={wanted}", f"paths.output_dir={tmp_path}",
    ]  # fmt: skip
    with pytest.raises(KeyboardInterrupt):
        command.fit(compose_config("fit_calibrated", overrides))
    assert seen == [wanted] and torch.get_num_threads() == before


def test_augmentation_noise_follows_the_data_rate_not_a_wrong_nominal_one(asl_root):
    """The per-sample std of a noise density depends on the rate: a sensor.rate_hz of 400 for 200-Hz data warns
    and uses the data's rate; one within 5 % of it is kept (so runs on EuRoC's 200.0026 Hz reproduce)."""
    import math

    from gyrodenoise.data.datamodule import ImuDataModule

    def gyro_std(rate_hz: float) -> float:
        sensor = {"rate_hz": rate_hz, "gyro_noise_density": 1e-4, "acc_noise_density": 1e-3}
        dm = ImuDataModule(name="my_imu", root=str(asl_root), train_seqs=["walk_1"], test_seqs=[], window=256,
                           sensor=sensor, augment={"noise_scale": 0.5})  # fmt: skip
        dm.setup("fit")
        dm.train_dataloader()
        return dm.augment.gyro_noise_std

    with pytest.warns(UserWarning, match=r"sensor.rate_hz=400, but the training sequences are sampled at 200\.0 Hz"):
        assert gyro_std(400.0) == pytest.approx(0.5 * 1e-4 * math.sqrt(200.0), rel=1e-6)
    assert gyro_std(205.0) == pytest.approx(0.5 * 1e-4 * math.sqrt(205.0))  # within 5 %: the nominal rate


def test_training_sequences_too_short_to_validate_are_named(tmp_path):
    """Recordings no longer than train_duration_s are trained on whole: with all of them so, validation was NaN and
    the safety net could not run, said only by Lightning's 'Total length of DataLoader ... is zero' (own-data
    walkthrough: 40-s recordings and the default 50 s)."""
    import warnings

    from _asl import write_asl_sequence

    from gyrodenoise.data.consistency import DataConsistencyWarning
    from gyrodenoise.data.datamodule import ImuDataModule

    for name, seconds in (("long", 8.0), ("short", 4.0)):
        write_asl_sequence(tmp_path / name, seconds=seconds, seed=len(name))
    split = {"name": "mine", "root": str(tmp_path), "test_seqs": [], "window": 256, "train_duration_s": 5.0}
    dm = ImuDataModule(train_seqs=["long", "short"], **split)
    with pytest.warns(DataConsistencyWarning, match=r"short \(4.0 s\) no longer than dataset.train_duration_s=5 "
                      "are trained on whole, so nothing of them validates"):  # fmt: skip
        dm.setup("fit")
    assert [s.name for s in dm.val_part] == ["long[5s:]"]
    dm = ImuDataModule(train_seqs=["short"], **split)
    with pytest.warns(DataConsistencyWarning, match="no validation data at all: the validation AOE is NaN"):
        dm.setup("fit")
    # 4 s against 3.9 s: a tail (20 samples) no longer than the loss's longest increment does not validate either
    with pytest.warns(DataConsistencyWarning, match=r"short \(4.0 s\) no longer than dataset.train_duration_s=3.9 "
                      r"plus the loss's longest increment \(32 samples\) are trained on whole"):  # fmt: skip
        ImuDataModule(train_seqs=["short"], **{**split, "train_duration_s": 3.9}).setup("fit")
    with warnings.catch_warnings():  # whole sequences asked for (train_duration_s: null): nothing to say
        warnings.simplefilter("error", DataConsistencyWarning)
        ImuDataModule(train_seqs=["short"], **{**split, "train_duration_s": None}).setup("fit")
