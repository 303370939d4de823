"""What a Hydra command prints also goes to its run folder's log (`<output dir>/<job name>.log`).

Hydra's log file receives only Python `logging` records, and the commands here report by printing (the
progress lines, the result tables, warnings, `error:` lines), so the file stayed empty. `console_to_job_log`
copies stdout and stderr into it while the command runs: a run on a cluster or in the background keeps its
console next to its outputs. Redrawn progress bars (text with carriage returns, only on a terminal) are not
copied; the plain progress lines printed without a terminal are.
"""

from __future__ import annotations

import io
import sys
import traceback
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TextIO

from hydra.core.hydra_config import HydraConfig


class _Tee(io.TextIOBase):
    """A text stream that writes to the console and, without bar redraws, to a log file.

    A logging handler made while a job ran keeps this stream after the job (Lightning's console handler, made at its
    import in the first job of a sequential sweep): once the job's log is closed, what it writes goes to the stream
    that stands in for `sys.<stream>` now, the next job's tee, not to the closed file."""

    def __init__(self, console: TextIO, log: TextIO, stream: str = "stderr") -> None:
        self.console, self.log, self.stream = console, log, stream

    def write(self, s: str) -> int:
        if self.log.closed:
            now = getattr(sys, self.stream)
            return (now if now is not self else self.console).write(s)
        self.console.write(s)
        if "\r" not in s and "\x1b[" not in s:  # a bar's redraw or cursor move (tqdm's nested bars) is not text
            self.log.write(s)
        return len(s)

    def flush(self) -> None:
        self.console.flush()
        if not self.log.closed:
            self.log.flush()

    def isatty(self) -> bool:  # the progress bar decides bars vs plain lines by the console
        return self.console.isatty()

    def fileno(self) -> int:
        return self.console.fileno()

    @property
    def encoding(self) -> str:  # type: ignore[override]
        return getattr(self.console, "encoding", "utf-8")


def write_to_job_log(text: str) -> None:
    """`text` into the run's log file only, e.g. the progress a terminal shows as a redrawn bar (not copied)."""
    if isinstance(sys.stdout, _Tee):
        sys.stdout.log.write(text)


def job_log_path(folder: str | Path | None = None) -> Path | None:
    """Hydra's log file of the running job (in `folder` when the command writes its outputs elsewhere than Hydra's
    run folder, e.g. evaluate's out_dir=...), or None outside a Hydra command."""
    if not HydraConfig.initialized():
        return None
    hc = HydraConfig.get()
    return Path(folder or hc.runtime.output_dir) / f"{hc.job.name}.log"


@contextmanager
def console_to_job_log(path: Path | None = None) -> Iterator[Path | None]:
    """Copy stdout and stderr into `path` (default: the Hydra job's log file) while the block runs."""
    default = job_log_path()
    path = path or default
    if path is None:
        yield None
        return
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError:  # a folder the command cannot write: its own error says so, in Hydra's run folder's log
        if default is None or path == default:
            raise
        path = default
    with open(path, "a", encoding="utf-8", buffering=1) as log:
        out, err = sys.stdout, sys.stderr
        sys.stdout, sys.stderr = _Tee(out, log, "stdout"), _Tee(err, log, "stderr")
        try:
            yield path
        except Exception:  # Hydra prints the traceback after this block: the log would end without it
            log.write(traceback.format_exc())
            raise
        finally:
            sys.stdout, sys.stderr = out, err
