"""Simulator settings a datasheet user gives: what the output carries, and one line for what no sensor has
(from an independent audit that checked the statistics with its own numpy/scipy code)."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest
import yaml
from scipy.signal import welch

from gyrodenoise.sim import build_effect, drone_trajectory, simulate_imu
from gyrodenoise.sim.dataset import SimDataModule, generate_sequence
from gyrodenoise.sim.effects import effect_from_config
from gyrodenoise.testworld import make_sequence


@pytest.fixture(scope="module")
def traj():
    return drone_trajectory(24.0, 3)


def _line_rms(x: np.ndarray, rate: float, f0: float) -> np.ndarray:
    """RMS per axis of x's line at f0, from its Welch power within +-1 Hz (an estimate of our own, not the
    detector's)."""
    f, p = welch(x - x.mean(0), fs=rate, nperseg=int(4 * rate), axis=0)
    return np.sqrt(p[np.abs(f - f0) <= 1.0].sum(0) * (f[1] - f[0]))


@pytest.mark.parametrize("f0", [40.25, 80.0])
def test_a_vibration_line_has_its_amplitude_in_the_output(traj, f0):
    """The amplitude is the line's in the IMU output (what the workflow fits and writes); before, the output's
    period mean took it down by ~sinc(f / rate): 0.94 at 40 Hz, 0.76 at 80 Hz."""
    amp = np.array([0.01, 0.02, 0.0])
    sim = simulate_imu(traj, [build_effect("vibration", frequency_hz=f0, amplitude=amp)], duration_s=20)
    rms = _line_rms(sim.gyro - sim.true_gyro, 200.0, f0)
    assert np.allclose(rms[:2], amp[:2] / np.sqrt(2), rtol=0.02)


def test_a_vibration_above_the_output_nyquist_is_refused(traj):
    with pytest.raises(ValueError, match="Nyquist"):
        simulate_imu(traj, [build_effect("vibration", frequency_hz=120.0, amplitude=[0.01, 0, 0])], duration_s=5)


def test_a_band_limited_vibration_past_the_output_nyquist_is_refused(traj):
    """Only the band's centre was checked: a band from 80 to 120 Hz at 200 Hz folded its upper half back into the
    output, which its amplitude and spectral shape do not describe."""
    band = build_effect("vibration", frequency_hz=100.0 - 10.0, bandwidth_hz=40.0, amplitude=[0.01, 0, 0])
    with pytest.raises(ValueError, match=r"'vibration': bandwidth_hz 40 .* reaches 110 Hz, past the IMU's Nyquist "
                       r"frequency \(100 Hz at 200 Hz\).*bandwidth_hz at most 20"):  # fmt: skip
        simulate_imu(traj, [band], duration_s=2)
    within = build_effect("vibration", frequency_hz=90.0, bandwidth_hz=20.0, amplitude=[0.01, 0, 0])
    assert np.isfinite(simulate_imu(traj, [within], duration_s=2).gyro).all()


@pytest.mark.parametrize("oversample", [1, 4])
def test_a_vibration_past_the_output_nyquist_is_refused_without_oversampling_too(traj, oversample):
    """At oversample=1 the band was silently cut at 0.49 x the rate (a band of another shape than the one given),
    and a line above the Nyquist frequency aliased; both are refused as they are where the simulator oversamples."""
    band = build_effect("vibration", frequency_hz=90.0, bandwidth_hz=40.0, amplitude=[0.01, 0, 0])
    with pytest.raises(ValueError, match=r"'vibration': bandwidth_hz 40 .* reaches 110 Hz, past the IMU's Nyquist "
                       r"frequency \(100 Hz at 200 Hz\).*bandwidth_hz at most 20"):  # fmt: skip
        simulate_imu(traj, [band], duration_s=2, oversample=oversample)
    line = build_effect("vibration", frequency_hz=120.0, amplitude=[0.01, 0, 0])
    with pytest.raises(ValueError, match=r"frequency_hz 120 is at or above the IMU's Nyquist frequency"):
        simulate_imu(traj, [line], duration_s=2, oversample=oversample)
    within = build_effect("vibration", frequency_hz=90.0, bandwidth_hz=20.0, amplitude=[0.01, 0, 0])
    assert np.isfinite(simulate_imu(traj, [within], duration_s=2, oversample=oversample).gyro).all()


def test_a_band_ending_just_under_the_nyquist_frequency_keeps_its_top_at_oversample_1(traj):
    """A band ending between 0.49 x the rate and the Nyquist frequency was cut at 0.49 x the rate without a word
    (96-100 Hz simulated as 96-98 Hz), and one starting above it crashed in scipy's filter design (review 63)."""
    band = build_effect("vibration", frequency_hz=97.0, bandwidth_hz=5.0, amplitude=[0.01, 0, 0])
    g = simulate_imu(traj, [band], duration_s=20, oversample=1).gyro[:, 0]
    f, p = welch(g - g.mean(), fs=200.0, nperseg=1024)
    assert p[(f > 98.3) & (f < 99.4)].mean() > 0.2 * p[(f > 95.0) & (f < 98.0)].mean()  # was 4e-4 x
    high = build_effect("vibration", frequency_hz=99.9, bandwidth_hz=0.1, amplitude=[0.01, 0, 0])
    with pytest.raises(ValueError, match=r"starts above 0.499 x the IMU's rate"):
        simulate_imu(traj, [high], duration_s=2, oversample=1)


def test_the_sim_dataset_checks_its_lists_before_it_simulates(tmp_path):
    """A sequence named twice was refused only after every sequence had been simulated and written (review 63)."""
    from gyrodenoise.cli_errors import ConfigError

    generation = {"seed": 0, "duration_s": 5, "error_model": []}
    with pytest.raises(ConfigError, match="dataset.train_seqs names drone_00 more than once"):
        SimDataModule(generation, root=str(tmp_path / "sim"), name="sim", train_seqs=["drone_00"] * 2, test_seqs=[])
    assert not (tmp_path / "sim").exists()


@pytest.mark.parametrize(
    ("content", "said"),
    [
        (None, "not found"),
        ("error_model: [{name: bias, params: {bias: 0.3}}", "while parsing"),  # malformed YAML
        ("error_model: [{name: bias, params: {bias: [0.3, 0.3, 0.3]}}]", "no 'units'"),
    ],
)
def test_a_bad_error_model_file_is_one_config_error(tmp_path, content, said):
    """A missing, malformed or refused error_model_file reached the user as a bare ValueError inside Hydra's 'Error in
    call to target' block: its reading ran before the settings' check that turns errors into one line."""
    from gyrodenoise.cli_errors import ConfigError

    path = tmp_path / "error_model.yaml"
    if content is not None:
        path.write_text(content)
    generation = {"seed": 0, "duration_s": 5, "error_model": [], "error_model_file": str(path)}
    with pytest.raises(ConfigError, match=rf"^dataset.generation.error_model_file={path}: .*{said}"):
        SimDataModule(generation, root=str(tmp_path / "sim"), name="sim", train_seqs=["drone_00"], test_seqs=[])
    assert not (tmp_path / "sim").exists()


def test_a_time_offset_delays_the_accelerometer_too(traj):
    """It is the IMU's stamps that are late: both sensors hold the motion of t - delta."""
    delta = 0.005
    plain = simulate_imu(traj, [], duration_s=10, acc_noise_density=0.0, oversample=4)
    late = simulate_imu(traj, [build_effect("time_offset", delta=delta)], duration_s=10, acc_noise_density=0.0,
                        oversample=4)  # fmt: skip
    # the delayed samples are the plain ones one sample-fraction earlier: compare with interpolation in time
    t = plain.t_ns * 1e-9
    for kind in ("gyro", "acc"):
        want = np.stack([np.interp(t - delta, t, getattr(plain, kind)[:, i]) for i in range(3)], 1)
        got = getattr(late, kind)
        inner = slice(10, -10)
        err = np.abs(got[inner] - want[inner]).max()
        assert err < 0.05 * np.abs(getattr(plain, kind)[inner] - want[inner]).max(), kind


def test_duration_is_the_span_of_the_stamps(tmp_path):
    """duration_s: 10 gave 11 s of data (the trajectory's 2 s of margin, less the simulator's 1 s)."""
    folder = generate_sequence(tmp_path, "drone_00", {"seed": 0, "duration_s": 10, "error_model": []})
    t = np.loadtxt(folder / "mav0" / "imu0" / "data.csv", delimiter=",", usecols=0, dtype=np.int64)
    assert (t[-1] - t[0]) == 10 * 10**9 and len(t) == 2001


@pytest.mark.parametrize(
    ("entry", "said"),
    [
        ({"name": "white_noise", "unit": "datasheet", "params": {"density": 0.5}}, "did you mean 'units'"),
        ({"name": "warmup_bias", "units": "si", "params": {"amplitude": 0.01, "tau": 0}}, "tau = 0 .* must be above 0"),
        ({"name": "sensor_bandwidth", "units": "si", "params": {"corner_hz": 0}}, "must be above 0"),
        ({"name": "saturation", "units": "si", "params": {"limit": 0}}, "must be above 0"),
    ],
)
def test_error_model_entries_no_sensor_has_are_named(entry, said):
    """A misspelt 'units' read 0.5 deg/sqrt(h) as 0.5 rad/s/sqrt(Hz) (3500x the noise) without a word."""
    with pytest.raises(ValueError, match=said):
        effect_from_config(entry)


def test_an_entry_without_units_is_refused_not_read_as_si(tmp_path):
    """An entry without 'units' was read as SI: the datasheet's 0.3 deg/s bias became 0.3 rad/s (57x) without a
    word. Refused now, naming the entry and the effect's datasheet units; dataset=sim before it simulates."""
    from gyrodenoise.cli_errors import ConfigError

    entry = {"name": "bias", "params": {"bias": [0.3, -0.2, 0.4]}}
    said = r"effect 'bias': no 'units'; add units: si \(SI\) or units: datasheet \(bias in deg/s\) to say which"
    with pytest.raises(ValueError, match=said):
        effect_from_config(entry)
    generation = {"seed": 0, "duration_s": 5, "error_model": [entry]}
    with pytest.raises(ConfigError, match=r"^dataset\.generation\.error_model\[0\]: " + said):
        SimDataModule(generation, root=str(tmp_path / "sim"), name="sim", train_seqs=["drone_00"], test_seqs=[])
    assert not (tmp_path / "sim").exists()
    with_units = effect_from_config({**entry, "units": "datasheet"})
    assert with_units.params["bias"] == pytest.approx(np.radians([0.3, -0.2, 0.4]))


def test_build_effect_checks_its_values_as_a_config_does():
    with pytest.raises(ValueError, match="must not be negative"):
        build_effect("white_noise", density=-1e-3)
    with pytest.raises(ValueError, match="unknown parameter"):
        build_effect("white_noise", sigma=1e-3)


@pytest.mark.parametrize(
    ("kwargs", "said"),
    [
        ({"rate_hz": 0}, "rate_hz=0"),
        ({"rate_hz": -200.0}, "rate_hz=-200"),
        ({"rate_hz": float("nan")}, "rate_hz=nan"),
        ({"oversample": 0}, "oversample=0"),
        ({"duration_s": -5.0}, "duration_s=-5"),
        ({"acc_noise_density": -1.0}, "acc_noise_density=-1"),
    ],
)
def test_simulator_settings_no_imu_has_are_one_line(traj, kwargs, said):
    """They gave a ZeroDivisionError, empty arrays or an all-NaN gyro."""
    with pytest.raises(ValueError, match=said):
        simulate_imu(traj, [], **kwargs)


def test_the_sim_datasets_noise_augmentation_follows_its_error_model(tmp_path):
    """dataset.sensor.gyro_noise_density was fixed at the ADIS16448's whatever gyro the error model simulated."""
    density = 5.0e-4
    generation = {
        "seed": 0,
        "duration_s": 5,
        "error_model": [{"name": "white_noise", "units": "si", "params": {"density": [density] * 3}}],
    }
    dm = SimDataModule(generation, root=str(tmp_path), name="sim", train_seqs=["drone_00"], test_seqs=[], sensor={})
    assert dm.sensor["gyro_noise_density"] == pytest.approx(density)
    kept = SimDataModule(generation, root=str(tmp_path), name="sim", train_seqs=["drone_00"], test_seqs=[],
                         sensor={"gyro_noise_density": 1e-4})  # fmt: skip
    assert kept.sensor["gyro_noise_density"] == 1e-4


VIBRATION_120HZ = {"name": "vibration", "units": "si", "params": {"frequency_hz": 120.0, "amplitude": [0.01, 0, 0],
                                                                   "bandwidth_hz": 0.0}}  # fmt: skip


@pytest.mark.parametrize(
    ("setting", "said"),
    [
        ({"rate_hz": -5}, r"^dataset\.generation\.rate_hz=-5\.0: the IMU rate in Hz"),
        ({"duration_s": "abc"}, r"^dataset\.generation\.duration_s='abc': give a number"),
        ({"acc_bias": [0, 0]}, r"^dataset\.generation\.acc_bias=\[0, 0\]: three finite numbers"),
        ({"acc_bias": "abc"}, r"^dataset\.generation\.acc_bias='abc': three numbers"),
        ({"error_model": [{"name": "bias", "units": "datasheet", "params": {"bias": [1, 2]}}]}, r"params\.bias"),
        (  # refused by the simulator only after 'simulating N sequence(s)', without the setting's name (review 63)
            {"error_model": [{"name": "white_noise", "units": "si", "params": {"density": 1e-4}}, VIBRATION_120HZ]},
            r"^dataset\.generation\.error_model\[1\]: effect 'vibration': frequency_hz 120 is at or above",
        ),
    ],
)
def test_sim_dataset_settings_are_config_errors_before_anything_is_simulated(tmp_path, setting, said):
    """A ConfigError is the commands' one 'error:' line; a plain ValueError reached the user inside Hydra's 'Error in
    call to target ... full_key: dataset' block, and rate_hz=-5 only after 'simulating 16 sequence(s) into ...'."""
    from gyrodenoise.cli_errors import ConfigError

    generation = {"seed": 0, "duration_s": 5, "error_model": [], **setting}
    with pytest.raises(ConfigError, match=said):
        SimDataModule(generation, root=str(tmp_path / "sim"), name="sim", train_seqs=["drone_00"], test_seqs=[])
    assert not (tmp_path / "sim").exists()


@pytest.mark.parametrize(
    ("kwargs", "said"),
    [
        ({"imu_rate_hz": 0.0}, "--imu-rate 0"),
        ({"oversample": 0}, "--oversample 0"),
        ({"imu_jitter": "-5us"}, "--imu-jitter -5us"),
        ({"imu_jitter": "3ms"}, "clipped at 0.4 of a period"),
    ],
)
def test_testworld_settings_no_imu_has_are_one_line(tmp_path, kwargs, said):
    with pytest.raises(ValueError, match=said):
        make_sequence(tmp_path, duration=2.0, **kwargs)


def test_a_vibration_read_from_an_error_model_file_is_named_by_the_file(tmp_path):
    """The early check blamed dataset.generation.error_model[i], a setting the user had not given (review 63)."""
    import yaml

    from gyrodenoise.cli_errors import ConfigError

    path = tmp_path / "error_model.yaml"
    path.write_text(yaml.safe_dump({"error_model": [VIBRATION_120HZ]}))
    generation = {"seed": 0, "duration_s": 5, "error_model": [], "error_model_file": str(path)}
    with pytest.raises(ConfigError, match=rf"^dataset\.generation\.error_model_file {path}, entry 0: effect 'vib"):
        SimDataModule(generation, root=str(tmp_path / "sim"), name="sim", train_seqs=["drone_00"], test_seqs=[])
    assert not (tmp_path / "sim").exists()


def test_an_oversampled_band_just_under_the_nyquist_frequency_is_simulated(traj):
    """The band filter's top edge (0.499 x the rate) binds only at oversample=1: oversampled, a band starting above
    it was accepted before the review's change and must still be (review 63)."""
    band = build_effect("vibration", frequency_hz=99.9, bandwidth_hz=0.1, amplitude=[0.01, 0, 0])
    assert np.isfinite(simulate_imu(traj, [band], duration_s=2).gyro).all()


@pytest.mark.parametrize("delta", [5.0, -20.0])
def test_a_time_offset_past_the_trajectorys_ends_is_refused(traj, delta):
    """The delayed motion was read from the spline's polynomial continuation beyond the truth's ends, silently: a
    time offset given in ms to build_effect (SI: s), delta=5, gave gyro rates of 14 rad/s and a specific force of
    500 m/s^2 on a hand-held flight whose rate stays under 3.6 rad/s; one past the trajectory's end did the same."""
    with pytest.raises(ValueError, match=r"time_offset.*delta .*s.*past the trajectory"):
        simulate_imu(traj, [build_effect("time_offset", delta=delta)], duration_s=5)
    sim = simulate_imu(traj, [build_effect("time_offset", delta=0.4)], duration_s=5)  # within the margin: as before
    assert np.isfinite(sim.gyro).all()
    # without a margin the grid itself reaches half a period past the ends: an offset of 0 adds nothing beyond it and
    # was refused ('delta 0 s reads the motion 0.00225 s after its end'); one that reads further is still refused
    assert np.isfinite(simulate_imu(traj, [build_effect("time_offset", delta=0.0)], margin_s=0).gyro).all()
    with pytest.raises(ValueError, match=r"delta 0.001 s reads the motion 0.001 s before its start"):
        simulate_imu(traj, [build_effect("time_offset", delta=1e-3)], margin_s=0)


def _entry(name: str, **params) -> dict:
    return {"name": name, "units": "si", "params": params}


def test_an_effect_given_twice_is_refused_where_its_entries_do_not_add_up(tmp_path, traj):
    """Two time_offset entries simulated the second alone (each reads the motion at t - delta, so 2 ms then 3 ms gave
    3 ms, not 5), without a word; noises, limits, low-passes and quantisers given twice do not add up either."""
    from gyrodenoise.cli_errors import ConfigError
    from gyrodenoise.sim.accel import acc_effects_from_config
    from gyrodenoise.sim.effects import effects_from_config
    from gyrodenoise.sim.error_model_file import load_error_model

    noise = _entry("white_noise", density=1e-4)
    twice = [_entry("time_offset", delta=0.002), noise, _entry("time_offset", delta=0.003)]
    said = (r"^dataset\.generation\.error_model\[2\]: effect 'time_offset' again, after "
            r"dataset\.generation\.error_model\[0\]: .*the second replaces the first.*; give one entry$")  # fmt: skip
    generation = {"seed": 0, "duration_s": 5, "error_model": twice}
    with pytest.raises(ConfigError, match=said):
        SimDataModule(generation, root=str(tmp_path / "sim"), name="sim", train_seqs=["drone_00"], test_seqs=[])
    assert not (tmp_path / "sim").exists()
    path = tmp_path / "error_model.yaml"  # a discrepancy run's file, edited by hand: named by the file
    path.write_text(yaml.safe_dump({"error_model": [noise, _entry("white_noise", density=2e-4)]}))
    with pytest.raises(ValueError, match=rf"^{path}: error_model\[1\]: effect 'white_noise' again, after {path}: "):
        load_error_model(path)
    for name, params in [("saturation", {"limit": 5.0}), ("sensor_bandwidth", {"corner_hz": 50.0}),
                         ("quantization", {"step": 1e-3}), ("bias_random_walk", {"density": 1e-5})]:  # fmt: skip
        with pytest.raises(ValueError, match=rf"^m\[1\]: effect '{name}' again, after m\[0\]"):
            effects_from_config([_entry(name, **params)] * 2, "m")
    with pytest.raises(ValueError, match=r"^acc\[1\]: effect 'bias_random_walk' again, after acc\[0\]"):
        acc_effects_from_config([_entry("bias_random_walk", density=1e-4)] * 2, "acc")


def test_effects_whose_entries_add_up_may_be_given_twice(traj):
    """A scale factor, a misalignment or a bias given twice is the one with the sum (each responds to the true
    input); several vibrations are several lines, as a discrepancy run writes them (`sim_model`)."""
    from gyrodenoise.sim.accel import acc_effects_from_config
    from gyrodenoise.sim.effects import effects_from_config

    kw = {"duration_s": 6, "oversample": 2, "seed": 1, "acc_noise_density": 0.0}
    split = [_entry("scale_factor", scale=[1e-3, 2e-3, -1e-3]), _entry("bias", bias=0.01),
             _entry("scale_factor", scale=[2e-3, 1e-3, 3e-3]), _entry("bias", bias=0.02)]  # fmt: skip
    summed = [_entry("scale_factor", scale=[3e-3, 3e-3, 2e-3]), _entry("bias", bias=0.03)]
    a = simulate_imu(traj, effects_from_config(split, "m"), **kw).gyro
    b = simulate_imu(traj, effects_from_config(summed, "m"), **kw).gyro
    assert np.allclose(a, b, rtol=0, atol=1e-12)
    lines = [_entry("vibration", frequency_hz=f, amplitude=0.01, bandwidth_hz=0.0) for f in (12.0, 31.0)]
    assert len(effects_from_config(lines, "m")) == 2
    assert len(acc_effects_from_config([_entry("misalignment", angles=1e-3)] * 2, "acc")) == 2


def _sim_data(generation: dict, root, names=("drone_00",)) -> SimDataModule:
    return SimDataModule(generation, root=str(root), name="sim", train_seqs=list(names), test_seqs=[])


def test_an_explicit_root_simulated_with_other_settings_is_refused(tmp_path):
    """dataset.root (a folder simulated before: here a cache folder sim-<hash>) was taken whatever settings made it:
    a run said seed 1 and a white noise, and trained on seed 0 without one. A mismatch with the folder's record is
    one line naming each setting that differs, before anything is simulated."""
    from gyrodenoise.cli_errors import ConfigError
    from gyrodenoise.sim.dataset import ensure_generated

    generation = {"seed": 0, "duration_s": 3, "rate_hz": 200.0, "error_model": []}
    root = ensure_generated(generation, ["drone_00"], tmp_path / "cache")
    _sim_data({**generation, "rate_hz": 200}, root, ["drone_00", "hand_00"])  # the same settings: more sequences
    other = {**generation, "seed": 1, "error_model": [_entry("white_noise", density=1e-4)]}
    said = (rf"^dataset\.root={root} was simulated with other settings than dataset\.generation \(error_model \(0 "
            r"entries there, 1 in the config\); seed 0 there, 1 in the config; its generation\.json\): delete the "
            r"folder to simulate it anew there, drop dataset\.root to use the cache folder of these settings, or give "
            r"dataset\.generation the folder's settings$")  # fmt: skip
    with pytest.raises(ConfigError, match=said):
        _sim_data(other, root, ["drone_00", "drone_01"])
    assert not (root / "drone_01").exists()  # refused before it simulated
    with pytest.raises(ConfigError, match=r"\(duration_s 3 there, 4 in the config; its generation\.json\)"):
        _sim_data({**generation, "duration_s": 4}, root)


def test_an_explicit_root_records_the_settings_it_was_simulated_with(tmp_path):
    """A folder simulated through dataset.root had no record, so nothing could hold a later run to its settings."""
    from gyrodenoise.cli_errors import ConfigError
    from gyrodenoise.sim.dataset import GENERATOR_VERSION

    root = tmp_path / "sim"
    generation = {"seed": 0, "duration_s": 3, "error_model": []}
    _sim_data(generation, root)
    record = json.loads((root / "generation.json").read_text())
    assert record == {"generator_version": GENERATOR_VERSION, "generation": generation, "names": ["drone_00"]}
    _sim_data(generation, root, ["drone_00", "hand_00"])
    assert json.loads((root / "generation.json").read_text())["names"] == ["drone_00", "hand_00"]
    with pytest.raises(ConfigError, match=r"\(seed 0 there, 2 in the config; its generation\.json\)"):
        _sim_data({**generation, "seed": 2}, root)


def test_an_explicit_root_without_a_record_is_warned_about_once(tmp_path):
    """A folder simulated before the record was written (or elsewhere) cannot be checked: a warning, once per
    folder, and no record written for it (it would vouch for sequences nobody checked). An empty one is recorded."""
    from gyrodenoise.sim.dataset import SimSettingsWarning

    root = tmp_path / "sim"
    generation = {"seed": 0, "duration_s": 3, "error_model": []}
    generate_sequence(root, "drone_00", generation)  # as the code before the record left it
    with pytest.warns(SimSettingsWarning, match=rf"^dataset\.root={root} has no generation\.json .* unchecked"):
        _sim_data(generation, root)
    with warnings.catch_warnings():
        warnings.simplefilter("error", SimSettingsWarning)
        _sim_data({**generation, "seed": 1}, root)  # said once; the other seed cannot be told from the folder
    assert not (root / "generation.json").exists()
    (tmp_path / "empty").mkdir()
    with warnings.catch_warnings():
        warnings.simplefilter("error", SimSettingsWarning)
        _sim_data(generation, tmp_path / "empty")
    assert (tmp_path / "empty" / "generation.json").is_file()
