"""Errors in what a user gave (a data folder, a file, a field) end a Hydra command with one line, not a traceback.

Hydra prints a full stack trace when the error is raised inside Lightning (the data are read in the
datamodule's setup), which buries the message that says what to do. The entry points wrap their work in
`user_errors()`: these errors print as ``error: <message>`` and exit with status 2; HYDRA_FULL_ERROR=1 (Hydra's
own switch) shows the trace as before.
"""

from __future__ import annotations

import errno
import functools
import importlib.util
import os
import re
import sys
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from typing import Any

from hydra.errors import InstantiationException
from omegaconf.errors import MissingMandatoryValue

from gyrodenoise.config import misspelt_key_message
from gyrodenoise.data.readers import DataFormatError
from gyrodenoise.notices import INTERRUPTED, plain_project_warnings
from gyrodenoise.pretrained import ModelFileError


class ConfigError(ValueError):
    """A config value the command cannot run with (e.g. `select=best`), found before any work is done."""


class TrainingDiverged(RuntimeError):
    """The loss or the validation AOE became NaN/inf during a fit: the weights are lost, continuing only burns time."""


USER_ERRORS = (DataFormatError, FileNotFoundError, ConfigError, ModelFileError, TrainingDiverged)
DISK_ERRNOS = (errno.ENOSPC, errno.EROFS, errno.EACCES, errno.EDQUOT)


@contextmanager
def user_errors() -> Iterator[None]:
    """Errors in what the user gave end the command with one line; the project's warnings print as one line too.
    So does Ctrl-C outside a fit (Hydra lets it through as a traceback), with the shell's status for SIGINT, 130;
    inside a fit Lightning catches it and `train` says how to resume."""
    try:
        with plain_project_warnings():
            yield
    except KeyboardInterrupt:
        if os.environ.get("HYDRA_FULL_ERROR") == "1":
            raise
        print(INTERRUPTED, file=sys.stderr)
        raise SystemExit(130) from None
    except USER_ERRORS as e:
        _one_line(str(e))
    except OSError as e:  # a full, read-only or forbidden disk: the path and what to do, not a traceback
        if e.errno not in DISK_ERRNOS:
            raise
        _one_line(
            f"{e.filename or 'writing a file'}: {e.strerror}. Free space or give a writable folder (hydra.run.dir=... "
            "for the outputs, GYRODENOISE_CACHE=... for the data cache)"
        )
    except MissingMandatoryValue as e:  # e.g. dataset=asl_folder without dataset.root
        _one_line(f"{e.full_key} has no value (it is '???' in the config): give it, e.g. {e.full_key}=...")
    except (InstantiationException, *_lightning_errors()) as e:  # Hydra wraps the Trainer's own error
        if isinstance(e.__cause__, USER_ERRORS):  # ours, raised inside a config's target (e.g. the data module)
            _one_line(str(e.__cause__))
        if "no supported gpu backend" not in str(e).lower():
            raise
        _one_line("no supported GPU backend on this machine: leave out trainer=gpu, or set trainer.accelerator=cpu.")


def _lightning_errors() -> tuple[type[Exception], ...]:
    """Lightning's configuration error, where Lightning is loaded (this module does not load it: a command that ends
    before any training would spend seconds importing it)."""
    module = sys.modules.get("lightning.fabric.utilities.exceptions")
    return (module.MisconfigurationException,) if module is not None else ()


def set_torch_threads(threads: Any) -> None:
    """`threads=N` of train and evaluate: torch's CPU threads, or torch's default when null. Checked here, so
    `threads=one` or `threads=0` ends the command with one line instead of a traceback or a silent default."""
    if threads is None:
        return
    if isinstance(threads, bool) or not isinstance(threads, int) or threads < 1:
        raise ConfigError(f"threads={threads!r}: a whole number >= 1, or threads=null (torch's default)")
    import torch

    torch.set_num_threads(threads)


@contextmanager
def torch_threads(threads: Any) -> Iterator[None]:
    """`set_torch_threads` for the length of a call: train() or evaluate() called from a notebook leaves the
    caller's thread count as it was."""
    import torch

    before = torch.get_num_threads()
    set_torch_threads(threads)
    try:
        yield
    finally:
        torch.set_num_threads(before)


def _one_line(message: str) -> None:
    """Called inside an `except` block: a bare raise re-raises the error being handled."""
    if os.environ.get("HYDRA_FULL_ERROR") == "1":
        raise  # noqa: PLE0704
    print(f"error: {message}\n(HYDRA_FULL_ERROR=1 shows the stack trace)", file=sys.stderr)
    raise SystemExit(2) from None


# config choices that need a package of an extra: (override pattern, module, extra)
PLUGINS = (
    (r"hydra/launcher=local", "hydra_plugins.hydra_joblib_launcher", "sweep"),
    (r"hparams_search=", "hydra_plugins.hydra_optuna_sweeper", "sweep"),
    (r"hydra/launcher=slurm", "hydra_plugins.hydra_submitit_launcher", "slurm"),
    (r"logger=.*\bmlflow\b", "mlflow", "mlflow"),  # logger=mlflow, logger=[tensorboard,mlflow]
)


def _installed(module: str) -> bool:
    """Whether `module` can be imported; find_spec raises, rather than answers no, when its parent package is
    missing too (hydra_plugins.* without any Hydra plugin installed)."""
    try:
        return importlib.util.find_spec(module) is not None
    except ModuleNotFoundError:
        return False


def missing_plugin_message(overrides: Sequence[str]) -> str | None:
    """What to install when a command line names a launcher, sweeper or logger whose package is not installed
    (Hydra says only "Could not load 'hydra/launcher/joblib'"; Lightning's logger a ModuleNotFoundError)."""
    for pattern, module, extra in PLUGINS:
        given = next((o for o in overrides if re.match(pattern, o)), None)
        if given is not None and not _installed(module):
            return (
                f"{given} needs a package that is not installed: pip install 'gyrodenoise[{extra}]' (from a "
                f"checkout: pip install -e '.[{extra}]')"
            )
    return None


SHOW_FLAGS = ("--cfg", "-c", "--info", "-i")


def flag_conflict_message(argv: Sequence[str]) -> str | None:
    """-m with --cfg or --info: Hydra ends it with "Only one of --run, --multirun, --cfg ..." as a traceback."""
    multirun = any(a in ("-m", "--multirun") for a in argv)
    show = next((a for a in argv if a in SHOW_FLAGS), None)
    if multirun and show:
        return (
            f"-m and {show} cannot be combined (Hydra does one of them): to see one job's config, drop -m and give "
            f"each swept key one value (e.g. seed=0 for seed=0,1) with {show}; to run the sweep, drop {show}"
        )
    return None


def hydra_key_hints(config_name: str) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """Wraps a `@hydra.main` entry point: a misspelt key on its command line ends it with one line that names
    the key it was probably meant to be (`misspelt_key_message`), before Hydra's own message."""

    def wrap(hydra_main: Callable[..., Any]) -> Callable[..., Any]:
        @functools.wraps(hydra_main)
        def main(*args: Any, **kwargs: Any) -> Any:
            if not args and not kwargs and os.environ.get("HYDRA_FULL_ERROR") != "1":
                argv = sys.argv[1:]
                if message := (
                    flag_conflict_message(argv)
                    or missing_plugin_message(argv)
                    or misspelt_key_message(config_name, argv)
                ):
                    print(f"error: {message}", file=sys.stderr)
                    raise SystemExit(2)
            return hydra_main(*args, **kwargs)

        return main

    return wrap
