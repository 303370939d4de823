"""The project's Hydra configs composed from Python (benchmarks, tests, notebooks).

The same files and defaults as the command lines (`python -m gyrodenoise.train ...`), without running a
Hydra app: `compose_config("train", ["dataset=euroc", "seed=3"])` is the config that
`python -m gyrodenoise.train dataset=euroc seed=3` would run (minus the `hydra` node).
"""

from __future__ import annotations

import difflib
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from hydra import compose, initialize_config_dir
from hydra.errors import ConfigCompositionException
from omegaconf import DictConfig, OmegaConf
from omegaconf.errors import ConfigAttributeError, ConfigKeyError, InterpolationResolutionError

CONF_DIR = Path(__file__).parent / "conf"


def _compose(name: str, overrides: Sequence[str]) -> DictConfig:
    with initialize_config_dir(str(CONF_DIR), version_base="1.3"):
        return compose(name, overrides=list(overrides))


def compose_config(name: str = "train", overrides: Sequence[str] = ()) -> DictConfig:
    """Config `name` (train, evaluate, fit_calibrated) of gyrodenoise/conf with Hydra `overrides` applied."""
    try:
        return _compose(name, overrides)
    except ConfigCompositionException as e:
        message = misspelt_key_message(name, list(overrides))
        if message is None:
            raise
        raise ConfigCompositionException(message) from e


def with_output_dir(cfg: DictConfig, key: str) -> Path:
    """`cfg.<key>` as a path; outside a Hydra command line it has no default (it is Hydra's run folder)."""
    try:
        return Path(OmegaConf.select(cfg, key, throw_on_missing=True))
    except InterpolationResolutionError:
        raise ValueError(
            f"{key} is Hydra's run folder by default, which exists only on the command line: from Python give it, "
            f"e.g. compose_config(..., ['{key}=outputs/my_run', ...])"
        ) from None


def misspelt_key_message(config_name: str, overrides: Sequence[str]) -> str | None:
    """What to say when `overrides` set a key that config `config_name` does not have, or None.

    Hydra's own message for `trainer.max_epoch=3` advises `+trainer.max_epoch=3`, which adds the key and then
    fails inside the Trainer; a misspelling deserves the key it was meant to be. Anything else (sweeps, Hydra's
    own settings, a missing config group option, whose message already lists the options) is left to Hydra.
    """
    if any(a.startswith("-") and a not in MULTIRUN_FLAGS for a in overrides):  # --config-name, ...: Hydra's business
        return None
    if message := unknown_list_option_message(overrides):
        return message
    plain = [
        one_sweep_value(a) for a in overrides if "=" in a and not a.startswith(("hydra.", "hydra/", "+", "~"))
    ]  # a sweep's keys are checked with its first value: a misspelt key fails every job
    try:
        _compose(config_name, plain)
        return None
    except ConfigCompositionException as e:
        key = getattr(e.__cause__, "full_key", None)
        if not isinstance(e.__cause__, (ConfigKeyError, ConfigAttributeError)) or not key:
            return None
    except Exception:  # noqa: BLE001 - the real run reports it
        return None
    groups = [a for a in plain if (CONF_DIR / a.split("=", 1)[0]).is_dir()]  # dataset=..., model=...: they shape it
    try:
        cfg = _compose(config_name, groups)
    except Exception:  # noqa: BLE001
        return None
    keys = _dotted_keys(cfg)
    if str(key) == "model._target_":  # a user's own class: another model kind, not a key of the denoiser's
        return (
            "model._target_ names a user's own network: give model=custom model._target_=PACKAGE.CLASS "
            "(docs/training.md, 'Your own network')"
        )
    if close := _close_keys(str(key), keys):
        return f"{key} is not a key of the '{config_name}' config: did you mean {' or '.join(close)}?"
    parent = key.rpartition(".")[0]
    siblings = [k.rpartition(".")[2] for k in keys if k.rpartition(".")[0] == parent and not k.endswith("_")]
    hint = f"{parent or 'The config'} has {', '.join(siblings)}. " if siblings else ""
    return f"{key} is not a key of the '{config_name}' config. {hint}To add a key the config lacks, write +key=value."


def unknown_list_option_message(overrides: Sequence[str]) -> str | None:
    """`logger=[tensorboard,mlflw]`: the group's option that does not exist, with the group's options (Hydra says
    only "Could not load 'logger/mlflw'" for a list; for one option it lists them itself)."""
    for override in overrides:
        group, _, value = one_sweep_value(override).lstrip("+").partition("=")
        folder = CONF_DIR / group
        if group.startswith("hydra") or not folder.is_dir() or not (value.startswith("[") and value.endswith("]")):
            continue
        options = sorted(f.stem for f in folder.glob("*.yaml"))
        for option in (o.strip() for o in value[1:-1].split(",") if o.strip()):
            if option not in options:
                close = difflib.get_close_matches(option, options, n=1)
                hint = f": did you mean {close[0]}?" if close else ""
                return (
                    f"{override}: '{group}' has no option {option}{hint} Its options: {', '.join(options)} "
                    "(or a config group of your own on the search path: hydra.searchpath)"
                )
    return None


MULTIRUN_FLAGS = ("-m", "--multirun")
SWEEP_FUNCTIONS = ("range(", "choice(", "interval(", "glob(", "tag(", "int(", "float(", "shuffle(", "sort(")


def one_sweep_value(override: str) -> str:
    """`key=a,b` (a multirun's sweep) as `key=a`; `key=range(...)` and the like as `key=0`; anything else as it is."""
    key, _, value = override.partition("=")
    if value.startswith(SWEEP_FUNCTIONS):
        return f"{key}=0"
    depth, quote = 0, ""
    for i, c in enumerate(value):  # the first comma outside brackets and quotes ends the first value
        if quote:
            quote = "" if c == quote else quote
        elif c in "'\"":
            quote = c
        elif c in "[({":
            depth += 1
        elif c in "])}":
            depth -= 1
        elif c == "," and depth == 0:
            return f"{key}={value[:i]}"
    return override


def _dotted_keys(node: Any, prefix: str = "") -> list[str]:
    if isinstance(node, DictConfig):
        node = OmegaConf.to_container(node, resolve=False)  # unresolved: '???' and ${...} stay as text
    keys = []
    for k, v in node.items():
        keys.append(f"{prefix}{k}")
        if isinstance(v, dict):
            keys += _dotted_keys(v, f"{prefix}{k}.")
    return keys


def _close_keys(key: str, keys: list[str]) -> list[str]:
    """Keys of the config close to `key`: a sibling with a similar name first, else a similar name anywhere."""
    parent, _, leaf = key.rpartition(".")
    siblings = {k.rpartition(".")[2]: k for k in keys if k.rpartition(".")[0] == parent}
    if close := difflib.get_close_matches(leaf, list(siblings), n=3, cutoff=0.75):
        return [siblings[c] for c in close]
    shallow = [k for k in keys if k.count(".") <= 1]  # e.g. max_epochs -> trainer.max_epochs
    return [k for k in shallow if difflib.get_close_matches(leaf, [k.rpartition(".")[2]], cutoff=0.8)][:3]
