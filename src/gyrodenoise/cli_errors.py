"""Errors in what a user gave (a data folder, a file, a field) end a Hydra command with one line, not a traceback.

Hydra prints a full stack trace when the error is raised inside Lightning (the data are read in the
datamodule's setup), which buries the message that says what to do. The entry points wrap their work in
`user_errors()`: these errors print as ``error: <message>`` and exit with status 2; HYDRA_FULL_ERROR=1 (Hydra's
own switch) shows the trace as before.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Iterator
from contextlib import contextmanager

from hydra.errors import InstantiationException
from lightning.fabric.utilities.exceptions import MisconfigurationException
from omegaconf.errors import MissingMandatoryValue

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


def _one_line(message: str) -> None:
    """Called inside an `except` block: a bare raise re-raises the error being handled."""
    if os.environ.get("HYDRA_FULL_ERROR") == "1":
        raise  # noqa: PLE0704
    print(f"error: {message}\n(HYDRA_FULL_ERROR=1 shows the stack trace)", file=sys.stderr)
    raise SystemExit(2) from None
