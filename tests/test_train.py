"""Training entry point on tiny synthetic data: seeded runs are reproducible, ckpt_path resumes."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

from gyrodenoise.cli_errors import TrainingDiverged
from gyrodenoise.config import compose_config
from gyrodenoise.lit import DenoiserModule
from gyrodenoise.train import format_test_table, schedule_cut_note, train


@pytest.fixture
def root(tiny_asl_root) -> Path:
    return tiny_asl_root


def tiny_dataset(root: Path) -> list[str]:
    """Overrides that train on the tiny synthetic sequences a, b and test on c."""
    return [
        "dataset=euroc",
        f"dataset.root={root}",
        "dataset.train_seqs=[a,b]",
        "dataset.test_seqs=[c]",
        "dataset.train_duration_s=4",
        "dataset.window=256",
        "dataset.gt_files={}",
        "dataset.eval_gt_variants={}",
    ]


def config(root: Path, out: Path, *extra: str):
    overrides = [
        *tiny_dataset(root),
        "model.channels=[4,8]",
        "model.dilations=[1,2]",
        "trainer.max_epochs=3",
        "trainer.check_val_every_n_epoch=1",
        "trainer.accelerator=cpu",
        "optim.scheduler.T_0=2",
        "logger=none",
        f"paths.output_dir={out}",
        *extra,
    ]
    return compose_config("train", overrides)


def test_seeded_runs_are_reproducible(root, tmp_path):
    a = train(config(root, tmp_path / "a", "seed=3"))
    b = train(config(root, tmp_path / "b", "seed=3"))
    sa = torch.load(tmp_path / "a" / "model.pt", weights_only=True)["state_dict"]
    sb = torch.load(tmp_path / "b" / "model.pt", weights_only=True)["state_dict"]
    for k in sa:
        torch.testing.assert_close(sa[k], sb[k], rtol=0, atol=0)
    assert a["val"]["val/aoe_deg"] == b["val"]["val/aoe_deg"]
    assert "test/aoe_deg" in a["test"] and (tmp_path / "a" / "summary.json").is_file()
    # the raw IMU as a reference: no correction model of any kind, so both runs agree and it is finite
    assert a["test"]["test/raw_imu_aoe_deg/c"] == b["test"]["test/raw_imu_aoe_deg/c"] > 0
    # the safety net: the calibrated baseline fitted on the same data, compared on the same validation
    safety = a["calibrated_baseline"]
    assert safety["beats_calibrated"] in (True, False) and safety["calibrated_test_aoe_deg"] > 0
    meta = torch.load(tmp_path / "a" / "model.pt", weights_only=True)["meta"]
    assert meta["beats_calibrated"] == safety["beats_calibrated"] and (tmp_path / "a" / "calibrated.pt").is_file()
    cal_meta = torch.load(tmp_path / "a" / "calibrated.pt", weights_only=True)["meta"]
    for fact in ("rate_hz", "train_seqs", "sensor", "dataset"):  # what correct's and evaluate's checks read
        assert cal_meta[fact] == meta[fact], fact
    table = format_test_table(a["test"])
    assert "| c |" in table and "| **average** |" in table and "nan" not in table
    with_cal = format_test_table(a["test"], safety["calibrated_test_aoe_deg_per_sequence"])
    assert "calibrated AOE 3D" in with_cal and "nan" not in with_cal
    assert f"{safety['calibrated_test_aoe_deg']:.2f} |" in with_cal.splitlines()[-1]  # the average row


def test_ckpt_path_resumes(root, tmp_path):
    # validation only after epoch 2: the best checkpoint stays at epoch 2, last.ckpt must still follow
    # every epoch (Lightning >= 2.6 would otherwise leave it at the last best one)
    first = config(root, tmp_path / "first", "trainer.max_epochs=3", "trainer.check_val_every_n_epoch=2")
    first.callbacks.last_checkpoint.every_n_epochs = 1  # the default (50) would not save in 3 epochs
    train(first)
    last = tmp_path / "first" / "checkpoints" / "last.ckpt"
    assert torch.load(last, weights_only=False)["epoch"] == 2
    # named by the epochs done, as the log counts them (Lightning's {epoch} would say 0001)
    assert [p.name for p in (tmp_path / "first" / "checkpoints").glob("best-*")] == ["best-epoch0002.ckpt"]
    # a checkpoint of a run takes the run's data facts and safety verdict from its model.pt
    from gyrodenoise.pretrained import load_model

    run_meta = torch.load(tmp_path / "first" / "model.pt", weights_only=True)["meta"]
    ckpt_meta = load_model(last)[1]
    assert ckpt_meta["rate_hz"] == run_meta["rate_hz"] and ckpt_meta["beats_calibrated"] == run_meta["beats_calibrated"]
    assert ckpt_meta["calibrated_model"] == str(tmp_path / "first" / "calibrated.pt")
    # copied out of its run, a checkpoint still knows its data (rate, training sequences), not the verdict
    import shutil

    alone = shutil.copy(last, tmp_path / "copied.ckpt")
    alone_meta = load_model(alone)[1]
    assert alone_meta["rate_hz"] == run_meta["rate_hz"] and alone_meta["train_seqs"] == ["a", "b"]
    assert "beats_calibrated" not in alone_meta
    resumed = train(config(root, tmp_path / "second", "trainer.max_epochs=4", f"ckpt_path={last}"))
    assert resumed["epochs"] == 4


def test_resumed_run_ends_on_the_uninterrupted_runs_weights(root, tmp_path):
    """A run stopped after epoch 2 and resumed from its last.ckpt ends with exactly the weights of the same run
    done in one go: the checkpoint carries the random stream (crops, dropout) with the optimiser state."""

    def run(out: str, epochs: int, *extra: str) -> dict:
        cfg = config(root, tmp_path / out, "seed=5", f"trainer.max_epochs={epochs}", "optim.scheduler.T_0=4", *extra)
        cfg.callbacks.last_checkpoint.every_n_epochs = 1
        train(cfg)
        return torch.load(tmp_path / out / "model.pt", weights_only=True)["state_dict"]

    whole = run("whole", 4)
    run("part", 2)
    resumed = run("resumed", 4, f"ckpt_path={tmp_path / 'part' / 'checkpoints' / 'last.ckpt'}")
    for k in whole:
        torch.testing.assert_close(resumed[k], whole[k], rtol=0, atol=0, msg=k)


def test_csv_logger_alone_writes_the_curves_and_the_test(root, tmp_path):
    """logger=csv: the validation curve and the test figures in csv/metrics.csv, no TensorBoard files."""
    import csv

    train(config(root, tmp_path / "run", "logger=csv"))
    rows = list(csv.DictReader((tmp_path / "run" / "csv" / "metrics.csv").open()))
    assert [r["epoch"] for r in rows if r.get("val/aoe_deg")] == ["0", "1", "2"]
    assert any(r.get("test/aoe_deg") for r in rows)
    assert not (tmp_path / "run" / "tensorboard").exists()


# experiment=sim_quick (the README's main job) cut to a few seconds of training
TINY_SIM = [
    "experiment=sim_quick",
    "dataset.generation.duration_s=12",
    "dataset.train_seqs=[drone_00]",
    "dataset.val_seqs=[hand_05]",
    "dataset.test_seqs=[drone_10]",
    "dataset.window=256",
    "model.channels=[4,8]",
    "model.dilations=[1,2]",
]


def test_main_job_logs_to_tensorboard_and_prints_epoch_lines(tmp_path, capsys):
    """experiment=sim_quick (the README's main job) on tiny settings: TensorBoard gets the scalars, the
    figures and the hparams; without a terminal the progress is one plain line every N epochs."""
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    overrides = [
        *TINY_SIM,
        "trainer.max_epochs=4",
        "trainer.check_val_every_n_epoch=2",
        "callbacks.progress_bar.print_every_n_epochs=2",
        "trainer.log_every_n_steps=2",
        f"paths.output_dir={tmp_path}",
    ]
    cfg = compose_config("train", overrides)
    train(cfg)
    out = capsys.readouterr().out
    lines = [ln for ln in out.splitlines() if ln.startswith("epoch ")]
    assert [ln.split(" | ")[0] for ln in lines] == ["epoch 2/4", "epoch 4/4"], out
    assert "left | train/loss " in lines[0] and "| val/aoe_deg " in lines[1], lines
    assert "\r" not in out and "Epoch 0" not in out  # no redrawn (per-epoch) tqdm bars in a log

    ev = EventAccumulator(str(tmp_path / "tensorboard"), size_guidance={"images": 0})
    ev.Reload()
    tags = ev.Tags()
    assert {"train/loss", "train/lr", "val/aoe_deg", "test/aoe_deg"} <= set(tags["scalars"]), tags["scalars"]
    assert [e.step for e in ev.Scalars("train/loss")] == [1, 3]  # every log_every_n_steps (one step per epoch)
    assert [e.step for e in ev.Scalars("train/lr")] == [1, 3]
    assert {"val/orientation", "val/gyro_correction"} <= set(tags["images"]), tags["images"]
    assert "_hparams_/session_start_info" in ev.summary_metadata
    # the hparams' metrics have tags of their own: the curves get no extra point at step 0
    assert 0 not in [e.step for e in ev.Scalars("val/aoe_deg")]
    assert [e.step for e in ev.Images("val/orientation")] == [e.step for e in ev.Scalars("val/aoe_deg")]
    assert "val/aoe_deg/hand_05" in tags["scalars"]  # each validation sequence
    assert "val/raw_imu_aoe_deg" in tags["scalars"]  # the reference the correction has to beat


def test_a_model_no_better_than_the_raw_gyro_is_said_so(root, tmp_path, capsys):
    """lr 0: the model stays the raw IMU (zero head, C_hat = I); the run's validation equals the raw gyro's."""
    summary = train(config(root, tmp_path, "optim.lr=0", "optim.scheduler.eta_min=0", "calibrated_baseline=false"))
    assert summary["val"]["val/aoe_deg"] == pytest.approx(summary["val"]["val/raw_imu_aoe_deg"])
    assert "is not better than the raw gyro's" in capsys.readouterr().out


def test_diverged_run_stops_with_one_line_and_no_model(tmp_path):
    """A NaN loss ends the fit at once with a message naming the epoch and what to change; no model.pt."""
    overrides = [
        *TINY_SIM,
        "trainer.max_epochs=20",
        "loss.weight=1e306",
        "logger=csv",
        f"paths.output_dir={tmp_path}",
    ]
    with pytest.raises(TrainingDiverged, match=r"at epoch \d+.*diverged.*optim\.lr") as e:
        train(compose_config("train", overrides))
    assert "no model.pt written" in str(e.value)
    assert not (tmp_path / "model.pt").exists() and not (tmp_path / "summary.json").exists()
    assert not (tmp_path / "checkpoints" / "interrupted.ckpt").exists()  # NaN weights: nothing to resume


def test_ema_run_also_tests_its_raw_final_weights(root, tmp_path):
    """callbacks=ema ships the averaged weights; test_other_rule also tests the final optimiser weights of
    the same run (a paired comparison), read back from the last checkpoint."""
    cfg = config(root, tmp_path / "ema", "callbacks=ema", "test_other_rule=true", "calibrated_baseline=false")
    cfg.callbacks.last_checkpoint.every_n_epochs = 1
    s = train(cfg)
    raw, ema = s["test_raw_final"]["test/aoe_deg"], s["test"]["test/aoe_deg"]
    assert raw > 0 and ema > 0 and raw != ema  # two different weight sets, both tested
    assert s["val_raw_final"]["val/aoe_deg"] != s["val"]["val/aoe_deg"]
    ckpt = torch.load(tmp_path / "ema" / "checkpoints" / "last.ckpt", weights_only=True)
    shipped = torch.load(tmp_path / "ema" / "model.pt", weights_only=True)["state_dict"]
    stats = [k for k in shipped if k.endswith(("running_mean", "running_var"))]
    assert stats
    for k, v in shipped.items():  # the shipped model is the average, not the raw weights ...
        if k not in stats and not k.endswith("num_batches_tracked"):
            torch.testing.assert_close(v, ckpt["state_dict"][f"model.{k}"])
    # ... with batch-norm statistics recomputed for it (not the averaged ones the checkpoint holds)
    assert all(not torch.allclose(shipped[k], ckpt["state_dict"][f"model.{k}"]) for k in stats)


def test_best_val_with_ema_scores_the_checkpoint_it_keeps(root, tmp_path):
    """select=best_val with callbacks=ema: the figures recorded are those of the checkpoint kept, not of the
    final averaged weights that the run's averaging callback would swap in during a post-fit validation."""
    from hydra.utils import instantiate

    from gyrodenoise.pretrained import load_model
    from gyrodenoise.train import _score_without_callbacks

    cfg = config(root, tmp_path / "emabest", "callbacks=ema", "select=best_val", "calibrated_baseline=false")
    s = train(cfg)
    dm = instantiate(cfg.dataset)
    kept = DenoiserModule.from_config(cfg)
    kept.model = load_model(tmp_path / "emabest" / "model.pt")[0]
    val, test = _score_without_callbacks(cfg, dm, kept)
    assert val["val/aoe_deg"] == pytest.approx(s["val"]["val/aoe_deg"], rel=1e-6)
    assert test["test/aoe_deg"] == pytest.approx(s["test"]["test/aoe_deg"], rel=1e-6)
    meta = torch.load(tmp_path / "emabest" / "model.pt", weights_only=True)["meta"]
    assert meta["val_aoe_deg"] == s["val"]["val/aoe_deg"]
    assert s["selected"].endswith(".ckpt") and "best-epoch" in s["selected"]


def test_a_run_without_lightnings_checkpoint_callbacks_keeps_its_final_weights(root, tmp_path, capsys):
    """With the best and last checkpoints turned off (e.g. to save I/O in a sweep) the only checkpoint callback left
    is the interruption one, which has no `monitor`: the run ended in an AttributeError after the fit, without
    model.pt. With callbacks=ema and test_other_rule the raw final weights are then simply not there to test."""
    off = ("~callbacks.model_checkpoint", "~callbacks.last_checkpoint", "calibrated_baseline=false")
    s = train(config(root, tmp_path / "plain", *off, "select=best_val"))
    assert (tmp_path / "plain" / "model.pt").is_file() and s["best_checkpoint"] == ""
    assert "no best checkpoint" in s["selected"]
    s = train(config(root, tmp_path / "ema", *off, "callbacks=ema", "test_other_rule=true"))
    assert (tmp_path / "ema" / "model.pt").is_file() and "test_raw_final" not in s
    assert "test_other_rule: the final weights without averaging are not scored" in capsys.readouterr().out  # said


def test_best_val_without_any_validation_says_so(root, tmp_path, capsys):
    s = train(
        config(
            root,
            tmp_path / "noval",
            "select=best_val",
            "trainer.check_val_every_n_epoch=50",
            "calibrated_baseline=false",
        )
    )
    out = capsys.readouterr().out
    assert "warning: select=best_val, but no validation ran" in out
    assert s["selection"] == "best_val" and "no best checkpoint" in s["selected"] and s["best_checkpoint"] == ""


@pytest.mark.parametrize(
    "override, message",
    [
        ("select=best", "select='best'"),
        ("optim.scheduler.name=cosine", "optim.scheduler.name='cosine'"),
        ("model.act=foo", "model.act='foo'"),
        # settings nothing reads: accepted and recorded in summary.json as if Adam or the schedule had used them
        ("+optim.betas=[0.9,0.99]", "optim.betas is not a setting of the optimiser"),
        ("+optim.scheduler.gamma=0.5", "optim.scheduler.gamma is not a setting of the schedule"),
    ],
)
def test_bad_choices_fail_before_the_fit(root, tmp_path, override, message):
    from gyrodenoise.cli_errors import ConfigError

    with pytest.raises(ConfigError, match=message):
        train(config(root, tmp_path / "bad", override))
    assert not (tmp_path / "bad" / "checkpoints").exists()  # nothing trained


@pytest.mark.parametrize(
    "override, message",
    [
        ("loss.increments=[0]", r"loss.increments=\[0\]"),  # was a ZeroDivisionError traceback
        ("loss.increments=16", "loss.increments=16"),  # was a TypeError traceback
        ("loss.increments=[16,16]", "distinct"),  # silently counted the 16-sample term twice
        ("loss.huber_delta=0", "loss.huber_delta=0"),  # was torch's RuntimeError at the first training step
        ("loss.huber_delta=-0.005", "loss.huber_delta=-0.005"),
        ("loss.weight=-1e6", "loss.weight=-1000000.0"),  # gradient ascent on the loss
        ("+loss.huber=0.01", "loss.huber is not a setting of the loss"),  # was a TypeError traceback
    ],
)
def test_bad_loss_settings_fail_before_any_data_are_read(root, tmp_path, override, message):
    from gyrodenoise.cli_errors import ConfigError
    from gyrodenoise.train import check_choices

    cfg = config(root, tmp_path / "bad", override)
    with pytest.raises(ConfigError, match=message):
        check_choices(cfg)
    with pytest.raises(ConfigError, match=message):
        train(cfg)
    assert not (tmp_path / "bad" / "checkpoints").exists()  # nothing trained


def test_recompute_batch_norm_averages_the_batch_statistics():
    """The first batch norm sees the convolution of the (deterministic) input: its recomputed running mean
    is the mean over the given batches of their per-batch channel means, whatever it held before."""
    from gyrodenoise.models.denoiser import DilatedCNNDenoiser
    from gyrodenoise.weight_averaging import recompute_batch_norm

    torch.manual_seed(0)
    model = DilatedCNNDenoiser(channels=(4, 8), dilations=(1, 2))
    bn = model.net[1]
    bn.running_mean.fill_(100.0)
    batches = [torch.randn(3, 200, 6) * (1 + i) for i in range(4)]
    recompute_batch_norm(model, batches)
    conv = model.net[0]
    expected = []
    with torch.no_grad():
        for imu in batches:
            x = ((imu - model.mean) / model.std).transpose(1, 2)
            x = torch.nn.functional.pad(x, (model.receptive_field - 1, 0), mode="replicate")
            expected.append(conv(x).mean(dim=(0, 2)))
    torch.testing.assert_close(bn.running_mean, torch.stack(expected).mean(0))
    assert not model.training or bn.momentum == 0.1  # mode and momentum restored


def test_test_data_is_checked_before_the_fit(root, tmp_path, capsys):
    """An empty test list or a bad test file ends the command before training, not after it; a test sequence
    that is also a training sequence is pointed out."""
    import shutil

    from gyrodenoise.cli_errors import ConfigError
    from gyrodenoise.data.readers import DataFormatError

    with pytest.raises(ConfigError, match="dataset.test_seqs is empty"):
        train(config(root, tmp_path / "empty", "dataset.test_seqs=[]"))
    bad = tmp_path / "data"
    shutil.copytree(root, bad)
    imu = bad / "c" / "mav0" / "imu0" / "data.csv"
    lines = imu.read_text().splitlines()
    stamp, *values = lines[9].split(",")
    other = ",".join([stamp, *(f"{float(v) + 0.1:.9f}" for v in values)])  # its stamp again, other values
    imu.write_text("\n".join([*lines[:10], other, *lines[10:]]) + "\n")
    with pytest.raises(DataFormatError, match="duplicate"):
        train(config(bad, tmp_path / "badtest"))
    assert not (tmp_path / "badtest" / "checkpoints").exists()
    train(config(root, tmp_path / "overlap", "dataset.test_seqs=[a]", "calibrated_baseline=false"))
    assert "test sequence(s) a are also training sequences" in capsys.readouterr().out


def test_an_unexpected_error_ends_up_in_the_run_log(tmp_path):
    from gyrodenoise.job_log import console_to_job_log

    log = tmp_path / "run" / "train.log"
    with pytest.raises(RuntimeError, match="boom"), console_to_job_log(log):
        print("epoch 1")
        raise RuntimeError("boom")
    text = log.read_text()
    assert "epoch 1" in text and "Traceback" in text and "RuntimeError: boom" in text


@pytest.mark.parametrize("schedule", ["constant", "cosine_warm_restarts"])
def test_the_learning_rate_is_logged_as_train_lr_for_either_schedule(schedule):
    cfg = compose_config("train", [*TINY_SIM, f"optim.scheduler.name={schedule}"])
    module = DenoiserModule.from_config(cfg)
    conf = module.configure_optimizers()
    sched = conf["lr_scheduler"]["scheduler"]
    assert conf["lr_scheduler"]["name"] == "train/lr"  # LearningRateMonitor's tag, not "lr-Adam"
    lr = cfg.optim.lr
    for _ in range(3):
        conf["optimizer"].step()
        sched.step()
    if schedule == "constant":
        assert sched.get_last_lr() == [lr]  # the placeholder scheduler changes nothing
    else:
        assert sched.get_last_lr()[0] < lr


def test_a_run_that_ends_inside_a_cosine_cycle_is_told(monkeypatch):
    def note(*overrides: str) -> str | None:
        return schedule_cut_note(compose_config("train", ["dataset=euroc", *overrides]))

    assert note() is None and note("experiment=paper_schedule") is None  # 600 = T_0; 1800 = 600 + 1200
    assert note("optim.scheduler.name=constant", "trainer.max_epochs=30") is None
    assert note("trainer.max_epochs=30", "optim.scheduler.T_0=30") is None
    short = note("trainer.max_epochs=30")
    assert "30 epochs into a 600-epoch cosine cycle" in short and "ends at 0.00994" in short
    assert "optim.scheduler.T_0=30" in short
    assert "300 epochs into a 1200-epoch" in note("experiment=paper_schedule", "trainer.max_epochs=900")


def test_an_installed_copy_records_the_commit_its_wheel_was_built_from(tmp_path, monkeypatch):
    """`pip install .` leaves no checkout beside the package: summary.json recorded only "0.1.0" for every commit
    (first-hour audit). setup.py writes the commit into the wheel; a checkout still answers for itself."""
    import json
    import subprocess

    import gyrodenoise
    from gyrodenoise.train import _code_version

    version = gyrodenoise.__version__
    site = tmp_path / "site-packages" / "gyrodenoise"
    site.mkdir(parents=True)
    monkeypatch.setattr(gyrodenoise, "__file__", str(site / "__init__.py"))
    assert _code_version() == {"package": version}  # no build record: the version only
    (site / "_build_info.json").write_text(json.dumps({"commit": "abc1234", "dirty": False}))
    assert _code_version() == {"package": version, "commit": "abc1234", "dirty": False, "built": True}

    repo = tmp_path / "checkout"  # a checkout around the package: its own commit, whatever a build left there
    (repo / "src" / "gyrodenoise").mkdir(parents=True)
    (repo / "pyproject.toml").write_text("[project]\nname = 'gyrodenoise'\n")
    (repo / "src" / "gyrodenoise" / "__init__.py").write_text("")
    (repo / "src" / "gyrodenoise" / "_build_info.json").write_text(json.dumps({"commit": "abc1234", "dirty": False}))
    git = ["git", "-c", "user.name=t", "-c", "user.email=t@t", "-C", str(repo)]
    for args in (["init", "-q"], ["add", "-A"], ["commit", "-qm", "x"]):
        subprocess.run(git + args, check=True, capture_output=True)
    head = subprocess.run(git + ["rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
    monkeypatch.setattr(gyrodenoise, "__file__", str(repo / "src" / "gyrodenoise" / "__init__.py"))
    assert _code_version() == {"package": version, "commit": head, "dirty": False}


def test_a_run_records_the_code_it_started_from(monkeypatch):
    """code_version is read once, before the first fit of the process: a commit or an edit of src/ while a run
    trains (minutes) is not the code it ran (a cross-validation recorded the commit made during its fourth fold)."""
    import gyrodenoise.train as t

    monkeypatch.setattr(t, "_LOADED_CODE", None)
    answers = iter([{"commit": "start"}, {"commit": "later", "dirty": True}])
    monkeypatch.setattr(t, "_code_version", lambda: next(answers))
    assert t.loaded_code_version() == {"commit": "start"} == t.loaded_code_version()
