"""Errors in what a user gave (a data folder, a file, a field) end a Hydra command with one line, not a traceback.

Hydra prints a full stack trace when the error is raised inside Lightning (the data are read in the
datamodule's setup), which buries the message that says what to do. The entry points wrap their work in
`user_errors()`: these errors print as ``error: <message>`` and exit with status 2; HYDRA_FULL_ERROR=1 (Hydra's
own switch) shows the trace as before.
"""

from __future__ import annotations

import difflib
import functools
import os
import sys
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from typing import Any

import torch
from hydra.errors import ConfigCompositionException, InstantiationException
from lightning.fabric.utilities.exceptions import MisconfigurationException
from omegaconf import DictConfig, OmegaConf
from omegaconf.errors import ConfigAttributeError, ConfigKeyError, MissingMandatoryValue

from gyrodenoise.config import CONF_DIR, compose_config
from gyrodenoise.data.readers import DataFormatError
from gyrodenoise.pretrained import ModelFileError


class ConfigError(ValueError):
    """A config value the command cannot run with (e.g. `select=best`), found before any work is done."""


USER_ERRORS = (DataFormatError, FileNotFoundError, ConfigError, ModelFileError)


@contextmanager
def user_errors() -> Iterator[None]:
    try:
        yield
    except USER_ERRORS as e:
        _one_line(str(e))
    except MissingMandatoryValue as e:  # e.g. dataset=asl_folder without dataset.root
        _one_line(f"{e.full_key} has no value (it is '???' in the config): give it, e.g. {e.full_key}=...")
    except (MisconfigurationException, InstantiationException) as e:  # Hydra wraps the Trainer's own error
        if "no supported gpu backend" not in str(e).lower():
            raise
        _one_line("no supported GPU backend on this machine: leave out trainer=gpu, or set trainer.accelerator=cpu.")


def set_torch_threads(threads: Any) -> None:
    """`threads=N` of train and evaluate: torch's CPU threads, or torch's default when null. Checked here, so
    `threads=one` or `threads=0` ends the command with one line instead of a traceback or a silent default."""
    if threads is None:
        return
    if isinstance(threads, bool) or not isinstance(threads, int) or threads < 1:
        raise ConfigError(f"threads={threads!r}: a whole number >= 1, or threads=null (torch's default)")
    torch.set_num_threads(threads)


def _one_line(message: str) -> None:
    """Called inside an `except` block: a bare raise re-raises the error being handled."""
    if os.environ.get("HYDRA_FULL_ERROR") == "1":
        raise  # noqa: PLE0704
    print(f"error: {message}\n(HYDRA_FULL_ERROR=1 shows the stack trace)", file=sys.stderr)
    raise SystemExit(2) from None


def misspelt_key_message(config_name: str, overrides: Sequence[str]) -> str | None:
    """What to say when `overrides` set a key that config `config_name` does not have, or None.

    Hydra's own message for `trainer.max_epoch=3` advises `+trainer.max_epoch=3`, which adds the key and then
    fails inside the Trainer; a misspelling deserves the key it was meant to be. Anything else (sweeps, Hydra's
    own settings, a missing config group option, whose message already lists the options) is left to Hydra.
    """
    if any(a.startswith("-") for a in overrides):  # -m, --config-name, ...: Hydra's business
        return None
    plain = [a for a in overrides if "=" in a and not a.startswith(("hydra.", "hydra/", "+", "~"))]
    try:
        compose_config(config_name, plain)
        return None
    except ConfigCompositionException as e:
        key = getattr(e.__cause__, "full_key", None)
        if not isinstance(e.__cause__, (ConfigKeyError, ConfigAttributeError)) or not key:
            return None
    except Exception:  # noqa: BLE001 - the real run reports it
        return None
    groups = [a for a in plain if (CONF_DIR / a.split("=", 1)[0]).is_dir()]  # dataset=..., model=...: they shape it
    try:
        cfg = compose_config(config_name, groups)
    except Exception:  # noqa: BLE001
        return None
    keys = _dotted_keys(cfg)
    if str(key) == "model._target_":  # a user's own class: another model kind, not a key of the denoiser's
        return "model._target_ names a user's own network: give model=custom model._target_=PACKAGE.CLASS (README)"
    if close := _close_keys(str(key), keys):
        return f"{key} is not a key of the '{config_name}' config: did you mean {' or '.join(close)}?"
    parent = key.rpartition(".")[0]
    siblings = [k.rpartition(".")[2] for k in keys if k.rpartition(".")[0] == parent and not k.endswith("_")]
    hint = f"{parent or 'The config'} has {', '.join(siblings)}. " if siblings else ""
    return f"{key} is not a key of the '{config_name}' config. {hint}To add a key the config lacks, write +key=value."


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


def hydra_key_hints(config_name: str) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """Wraps a `@hydra.main` entry point: a misspelt key on its command line ends it with one line that names
    the key it was probably meant to be (`misspelt_key_message`), before Hydra's own message."""

    def wrap(hydra_main: Callable[..., Any]) -> Callable[..., Any]:
        @functools.wraps(hydra_main)
        def main(*args: Any, **kwargs: Any) -> Any:
            if not args and not kwargs and os.environ.get("HYDRA_FULL_ERROR") != "1":
                if message := misspelt_key_message(config_name, sys.argv[1:]):
                    print(f"error: {message}", file=sys.stderr)
                    raise SystemExit(2)
            return hydra_main(*args, **kwargs)

        return main

    return wrap
