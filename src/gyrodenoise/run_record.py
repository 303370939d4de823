"""A refused rerun in a run's folder leaves that run's Hydra record (`.hydra/`) as it was.

Hydra writes `.hydra/config.yaml`, `hydra.yaml` and `overrides.yaml` before the task starts, so a rerun in the
same folder (`hydra.run.dir=...`, to resume or to add folds) that the task then refuses (a `ConfigError`: other
settings than the folder's run, a damaged checkpoint) would leave a record of the refused command beside the
outputs of the run that made them. `KeepRunRecord` (a Hydra callback of `train`) keeps the record found at the
start of a single run; `restored_on_refusal` puts it back when the task refuses to run.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from hydra.experimental.callback import Callback
from omegaconf import DictConfig

from gyrodenoise.atomic import atomic_path
from gyrodenoise.cli_errors import ConfigError

_kept: dict[Path, bytes | None] = {}  # the record at the start of this process's single run (None: not there)


class KeepRunRecord(Callback):
    """Reads the run folder's Hydra record before Hydra rewrites it (single runs; a sweep's jobs get new folders)."""

    def on_run_start(self, config: DictConfig, **kwargs: Any) -> None:
        _kept.clear()
        if config.hydra.output_subdir is None:
            return
        record = Path(config.hydra.run.dir) / config.hydra.output_subdir
        for name in ("config.yaml", "hydra.yaml", "overrides.yaml"):
            path = record / name
            _kept[path] = path.read_bytes() if path.is_file() else None


def restore_run_record() -> None:
    """Put back the record `KeepRunRecord` found: the files the refused command wrote are removed if there were
    none (a fresh folder keeps what Hydra wrote: it holds no other run)."""
    if not any(data is not None for data in _kept.values()):
        return
    for path, data in _kept.items():
        if data is None:
            path.unlink(missing_ok=True)
            continue
        with atomic_path(path) as tmp:
            tmp.write_bytes(data)


@contextmanager
def restored_on_refusal() -> Iterator[None]:
    """Around a task: a `ConfigError` (found before any work is done) restores the folder's previous record, one
    raised inside a config's target too (the data module's: Hydra's instantiate raises it as the cause of its own
    InstantiationException)."""
    try:
        yield
    except Exception as e:
        if isinstance(e, ConfigError) or isinstance(e.__cause__, ConfigError):
            restore_run_record()
        raise
