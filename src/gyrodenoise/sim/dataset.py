"""`dataset=sim`: EuRoC-like drone and hand-held sequences simulated with a realistic error model,
generated on first use into the cache and then read through the normal ASL loaders.

The cache folder is keyed by a hash of the generation settings ($GYRODENOISE_CACHE or
~/.cache/gyrodenoise, folder sim-<hash>), so changing any setting gives a new data set and an
unchanged one is never regenerated. Sequence names say the trajectory kind: drone_*, hand_*.

Every folder it generates records its settings (generation.json). An explicit `dataset.root` is held to them: a
folder simulated with other settings than the config's is refused, naming the settings that differ, and one without
a record (simulated before it was written, or not simulated here) is taken with a warning.
"""

from __future__ import annotations

import hashlib
import json
import warnings
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import yaml

from gyrodenoise.atomic import write_text
from gyrodenoise.cli_errors import ConfigError
from gyrodenoise.data.cache import default_cache_dir
from gyrodenoise.data.datamodule import ImuDataModule, check_sequence_lists
from gyrodenoise.sim.accel import acc_effects_from_config
from gyrodenoise.sim.effects import Bias, Effect, Vibration, WhiteNoise, effects_from_config
from gyrodenoise.sim.error_model_file import load_error_model
from gyrodenoise.sim.imu import _check_settings, asl_written, simulate_imu, write_asl
from gyrodenoise.sim.trajectory import drone_trajectory, handheld_trajectory

# 2: sequences last duration_s (they ran 1 s longer), the accelerometer follows a time offset, vibration
# amplitudes are the output's
GENERATOR_VERSION = 2
KINDS = {"drone": drone_trajectory, "hand": handheld_trajectory}


# settings added since, at the value that simulates what was simulated before them: left out of the key, so the data
# sets generated before they existed keep their folders
NEUTRAL_SETTINGS = {"acc_error_model": ([], None)}


# what the generation takes for a setting left out (and a folder whose record leaves one out was simulated at)
GENERATION_DEFAULTS = {
    "seed": 0,
    "duration_s": 120.0,
    "rate_hz": 200.0,
    "acc_noise_density": 2.0e-3,
    "acc_bias": [0.0, 0.0, 0.0],
    "bias_jitter_rad_s": 0.0,
    "error_model": [],
    "acc_error_model": [],
}
RECORD = "generation.json"  # a generated folder's settings, beside its sequences


class SimSettingsWarning(UserWarning):
    """A folder of simulated sequences whose generation settings cannot be checked against the config's."""


_UNRECORDED_WARNED: set[Path] = set()  # folders without a record already warned about: once per process


def generation_key(generation: Mapping, names: list[str]) -> str:
    gen = {k: v for k, v in generation.items() if not (k in NEUTRAL_SETTINGS and v in NEUTRAL_SETTINGS[k])}
    blob = json.dumps({"v": GENERATOR_VERSION, "gen": gen, "names": sorted(names)}, sort_keys=True)
    return hashlib.sha1(blob.encode()).hexdigest()[:12]


def _sequence_seed(base_seed: int, name: str) -> int:
    return int.from_bytes(hashlib.sha1(f"{base_seed}:{name}".encode()).digest()[:4], "little")


def _error_models(generation: Mapping) -> tuple[list[Effect], list, float]:
    """The gyro's and the accelerometer's error effects and the turn-on bias spread of `generation` (ValueError
    naming the setting when one is not valid)."""
    entries = [dict(c) if hasattr(c, "keys") else c for c in generation.get("error_model", [])]  # DictConfig -> dict
    effects: list[Effect] = effects_from_config(entries, "dataset.generation.error_model")
    acc_entries = generation.get("acc_error_model") or []
    if isinstance(acc_entries, str | Mapping):  # a list is iterable; a mapping or a string would read as its keys
        raise ValueError(
            f"dataset.generation.acc_error_model={acc_entries!r}: a list of {{name, units, params}} entries (or [])"
        )
    acc_entries = [dict(c) if hasattr(c, "keys") else c for c in acc_entries]
    acc_effects = acc_effects_from_config(acc_entries, "dataset.generation.acc_error_model")
    # the turn-on bias: differs per sequence
    jitter = float(generation.get("bias_jitter_rad_s", GENERATION_DEFAULTS["bias_jitter_rad_s"]))
    if not jitter >= 0:  # NaN included
        raise ValueError(f"dataset.generation.bias_jitter_rad_s={jitter!r}: the turn-on bias spread in rad/s, >= 0")
    return effects, acc_effects, jitter


def check_generation(generation: Mapping, model_file: str | None = None) -> None:
    """The generation settings, checked before anything is simulated or a cache folder made: a ConfigError (one line
    from the commands, not Hydra's 'Error in call to target' block) naming the dataset.generation setting
    (`model_file`: the error_model_file its error model was read from)."""
    values = {}
    for key in ("rate_hz", "duration_s", "acc_noise_density"):
        try:
            values[key] = float(generation.get(key, GENERATION_DEFAULTS[key]))
        except (ValueError, TypeError):
            raise ConfigError(f"dataset.generation.{key}={generation.get(key)!r}: give a number") from None
    acc_bias = generation.get("acc_bias", GENERATION_DEFAULTS["acc_bias"])
    try:
        np.asarray(acc_bias, dtype=np.float64)
    except (ValueError, TypeError):
        raise ConfigError(f"dataset.generation.acc_bias={acc_bias!r}: three numbers in m/s^2") from None
    try:
        effects = _error_models(generation)[0]
        _check_settings(values["rate_hz"], values["duration_s"], 1, values["acc_noise_density"], acc_bias)
        for i, e in enumerate(effects):  # one per entry (error_model_file's included): else refused mid-simulation
            band = (float(e.params["frequency_hz"]), float(e.params["bandwidth_hz"])) if e.name == "vibration" else None
            if band and (problem := Vibration.rate_problem(*band, values["rate_hz"])):
                where = f"error_model_file {model_file}, entry {i}" if model_file else f"error_model[{i}]"
                raise ValueError(f"dataset.generation.{where}: {problem}")
    except (ValueError, TypeError) as e:
        message = str(e)  # simulate_imu's own names (rate_hz=..., acc_bias=...) are settings of dataset.generation
        raise ConfigError(message if message.startswith("dataset.") else f"dataset.generation.{message}") from None


def generate_sequence(folder: Path, name: str, generation: Mapping) -> Path:
    kind = name.split("_")[0]
    if kind not in KINDS:
        raise ValueError(f"simulated sequence {name!r}: the name must start with one of {sorted(KINDS)} + '_'")
    seed = _sequence_seed(int(generation.get("seed", GENERATION_DEFAULTS["seed"])), name)
    rng = np.random.default_rng(seed)
    duration = float(generation.get("duration_s", GENERATION_DEFAULTS["duration_s"]))
    traj = KINDS[kind](duration + 2.0, int(rng.integers(1 << 30)))
    effects, acc_effects, jitter = _error_models(generation)
    if jitter > 0:
        effects.append(Bias(bias=rng.normal(0.0, jitter, 3)))
    sim = simulate_imu(
        traj,
        effects,
        rate_hz=float(generation.get("rate_hz", GENERATION_DEFAULTS["rate_hz"])),
        duration_s=duration,
        seed=int(rng.integers(1 << 30)),
        acc_noise_density=float(generation.get("acc_noise_density", GENERATION_DEFAULTS["acc_noise_density"])),
        acc_bias=tuple(generation.get("acc_bias", GENERATION_DEFAULTS["acc_bias"])),
        acc_effects=acc_effects,
    )
    # several jobs may generate the same data set at once (a job array on a fresh cache): the first copy stays
    return write_asl(folder / name, sim, keep_existing=True)


def ensure_generated(generation: Mapping, names: list[str], cache_dir: str | Path | None = None) -> Path:
    """The data-set folder, generating the sequences that are not there yet."""
    root = Path(cache_dir or default_cache_dir()) / f"sim-{generation_key(generation, names)}"
    missing = [n for n in names if not asl_written(root / n)]
    if missing:  # tens of seconds: say what the wait is for, and where the data go
        print(f"simulating {len(missing)} sequence(s) into {root} (once: later runs with these settings read them)")
    for name in missing:
        if not asl_written(root / name):  # another job on the same cache may have written it meanwhile
            generate_sequence(root, name, generation)
    _write_record(root, generation, names)
    return root


def _write_record(root: Path, generation: Mapping, names: list[str]) -> None:
    """The folder's settings record (atomically: a job reading it never sees half of one), rewritten only when it
    changes (many jobs of an array may use one folder)."""
    record = json.dumps({"generator_version": GENERATOR_VERSION, "generation": generation, "names": names}, indent=2)
    settings = root / RECORD
    if not settings.is_file() or settings.read_text() != record:
        write_text(settings, record)


def _comparable(generation: Mapping) -> dict:
    """The settings that make the data: defaults filled in, neutral settings at their neutral value, and an entry
    without 'units' as SI (how the records written before units was required read it)."""
    out = {**GENERATION_DEFAULTS, **generation}
    out.pop("error_model_file", None)  # replaced by its content (`with_error_model_file`)
    for key, neutral in NEUTRAL_SETTINGS.items():
        if out.get(key) in neutral:
            out[key] = neutral[0]
    for key in ("error_model", "acc_error_model"):
        if isinstance(out[key], list):
            out[key] = [{"units": "si", **e} if isinstance(e, dict) else e for e in out[key]]
    return out


def _differences(recorded: dict, config: dict) -> list[str]:
    """The settings that differ, each in a few words ('seed 0 there, 1 in the config', 'error_model[2]')."""
    out = []
    for key in sorted(set(recorded) | set(config)):
        was, now = recorded.get(key), config.get(key)
        if was == now:
            continue
        if key.endswith("error_model") and isinstance(was, list) and isinstance(now, list):
            if len(was) != len(now):
                out.append(f"{key} ({len(was)} entries there, {len(now)} in the config)")
            else:
                i = next(i for i, (a, b) in enumerate(zip(was, now, strict=True)) if a != b)
                name = now[i].get("name") if isinstance(now[i], dict) else None
                out.append(f"{key}[{i}]" + (f" ({name})" if name else ""))
            continue
        there, here = json.dumps(was), json.dumps(now)
        out.append(f"{key} {there} there, {here} in the config" if len(there + here) < 60 else key)
    return out


def check_recorded(root: Path, generation: Mapping) -> list[str] | None:
    """The sequences the explicit folder `root` records, whose settings must be `generation`'s (ConfigError naming
    those that differ). None where it records none: a folder with sequences in it is then warned about once (they may
    have been simulated with any settings), an empty or new one is not (it will be simulated here)."""
    path = root / RECORD
    if not path.is_file():
        if root.is_dir() and any(root.iterdir()) and root.resolve() not in _UNRECORDED_WARNED:
            _UNRECORDED_WARNED.add(root.resolve())
            warnings.warn(
                f"dataset.root={root} has no {RECORD} (simulated before it was recorded, or elsewhere): its sequences "
                "are taken as simulated with dataset.generation's settings, unchecked; delete the folder to simulate "
                "it anew with them",
                SimSettingsWarning,
                stacklevel=3,
            )
        return None
    try:
        record = json.loads(path.read_text())
        recorded = _comparable(record["generation"])
    except (ValueError, KeyError, TypeError):
        raise ConfigError(
            f"dataset.root={root}: {path} is not a generation record (JSON with 'generation'); delete the folder to "
            "simulate it anew, or drop dataset.root to use the cache"
        ) from None
    differ = _differences(recorded, _comparable(generation))
    version = record.get("generator_version")
    if version is not None and version != GENERATOR_VERSION:  # records before it was written: the settings alone
        differ.insert(0, f"generator_version {version} there, {GENERATOR_VERSION} in this code")
    if differ:
        raise ConfigError(
            f"dataset.root={root} was simulated with other settings than dataset.generation ({'; '.join(differ)}; "
            f"its {RECORD}): delete the folder to simulate it anew there, drop dataset.root to use the cache folder "
            "of these settings, or give dataset.generation the folder's settings"
        )
    return list(record.get("names", []))


def with_error_model_file(gen: dict) -> dict:
    """`error_model_file` (a discrepancy run's error_model.yaml) replaces `error_model` and `bias_jitter_rad_s` by
    the file's content, so the cache key follows the model, not the path; absent or null: unchanged."""
    path = gen.pop("error_model_file", None)
    if path is None:
        return gen
    gen["error_model"], jitter = load_error_model(path, float(gen.get("rate_hz", GENERATION_DEFAULTS["rate_hz"])))
    if jitter is not None:
        gen["bias_jitter_rad_s"] = float(jitter)
    return gen


def white_noise_density(entries: list) -> float:
    """The gyro white-noise density (rad/s/sqrt(Hz), mean over the axes) of an error-model list; 0 without one."""
    effects = effects_from_config([dict(c) for c in entries], "dataset.generation.error_model")
    found = [e for e in effects if isinstance(e, WhiteNoise)]
    return float(np.mean([e.params["density"] for e in found])) if found else 0.0


class SimDataModule(ImuDataModule):
    """ImuDataModule over simulated sequences generated on first use (see module docstring)."""

    def __init__(self, generation: Mapping, root: str | None = None, cache_dir: str | None = None, **kwargs) -> None:
        lists = [kwargs.get(k) for k in ("train_seqs", "test_seqs", "val_seqs", "cv_fold")]
        check_sequence_lists(*lists)  # before minutes of simulation, not after them
        names = sorted(set(kwargs.get("train_seqs", [])) | set(kwargs.get("test_seqs", [])))
        names = sorted(set(names) | set(kwargs.get("val_seqs") or []))
        model_file = generation.get("error_model_file")
        try:
            gen = with_error_model_file(json.loads(json.dumps(dict(generation))))  # plain data for hashing
        except (ValueError, TypeError, OSError, yaml.YAMLError) as e:  # one line, not Hydra's instantiation block
            raise ConfigError(f"dataset.generation.error_model_file={model_file}: {e}") from None
        check_generation(gen, model_file)
        sensor = dict(kwargs.get("sensor") or {})
        if sensor.get("gyro_noise_density") is None:  # the simulated gyro's own, for the training's noise augmentation
            sensor["gyro_noise_density"] = white_noise_density(gen.get("error_model", []))
            kwargs["sensor"] = sensor
        if root:  # an explicit folder: held to its record of settings, then the missing sequences generated there
            data_root = Path(root)
            recorded = check_recorded(data_root, gen)
            # a folder with unrecorded sequences is not given a record: it would vouch for data it never checked
            unrecorded = recorded is None and data_root.is_dir() and any(data_root.iterdir())
            for name in names:
                if not asl_written(data_root / name):
                    generate_sequence(data_root, name, gen)
            if not unrecorded:
                _write_record(data_root, gen, sorted(set(recorded or []) | set(names)))
        else:
            data_root = ensure_generated(gen, names, cache_dir)
        super().__init__(root=str(data_root), cache_dir=cache_dir, **kwargs)
        self.generation = gen
