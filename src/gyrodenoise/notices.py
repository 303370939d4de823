"""Third-party messages that say nothing about the user's run, kept out of its output.

Lightning 2.6 advertises a cloud logger at every Trainer start and notes that a ModelSummary callback is configured
(conf/callbacks/default.yaml sets one on purpose, for a plain-text summary); Lightning 2.6 and torch.export under
torch 2.13 warn that `isinstance(treespec, LeafSpec)` is deprecated, inside their own code; torch's ONNX exporter
logs, once per operator, that torchvision (which no gyrodenoise model uses) is not installed; onnxscript logs a
failed conversion to another ONNX opset with the ONNX C API's traceback, which `export --opset` then says in one line
(`export.export_onnx`). Everything else they log or warn is left alone.
"""

from __future__ import annotations

import contextlib
import functools
import logging
import sys
import warnings
from collections.abc import Callable, Iterator
from typing import Any

LIGHTNING_LOGGER = "lightning.pytorch.utilities.rank_zero"
ONNX_REGISTRATION_LOGGER = "torch.onnx._internal.exporter._registration"
ONNX_CONVERTER_LOGGER = "onnxscript.version_converter"
NOISE_PREFIXES = {  # logger -> message starts to drop
    LIGHTNING_LOGGER: ("💡 Tip:", "Trainer already configured with model summary callbacks"),
    ONNX_REGISTRATION_LOGGER: ("torchvision is not installed",),
    ONNX_CONVERTER_LOGGER: ("Failed to convert the model to the target version",),
}
LEAFSPEC_DEPRECATION = r"`isinstance\(treespec, LeafSpec\)` is deprecated"
# LearningRateMonitor wraps each logged rate in torch.tensor(); with the CUDA-graph step the rate is already a tensor
# (Adam's capturable form), and torch says "To copy construct from a tensor ..." at every logged rate
TENSOR_COPY_NOTICE = r"To copy construct from a tensor"


class _DropNoise(logging.Filter):
    def __init__(self, prefixes: tuple[str, ...]) -> None:
        super().__init__()
        self.prefixes = prefixes

    def filter(self, record: logging.LogRecord) -> bool:
        return not record.getMessage().startswith(self.prefixes)


def quiet_library_notices() -> None:
    """Drop the messages above (idempotent: the log filter is added once)."""
    for name, prefixes in NOISE_PREFIXES.items():
        log = logging.getLogger(name)
        if not any(isinstance(f, _DropNoise) for f in log.filters):
            log.addFilter(_DropNoise(prefixes))
    warnings.filterwarnings("ignore", message=LEAFSPEC_DEPRECATION)
    warnings.filterwarnings("ignore", message=TENSOR_COPY_NOTICE, module=r"lightning\.pytorch\.callbacks\.lr_monitor")


@contextlib.contextmanager
def plain_project_warnings() -> Iterator[None]:
    """Inside a command: gyrodenoise's own warnings (data, sanity, model quality) print as `warning: <message>`, like
    the commands' other lines, not as Python's `<file>:<line>: <Category>: ...` plus the source line of the
    `warnings.warn` call, which reads like a crash. Other packages' warnings keep Python's format."""
    plain = warnings.formatwarning

    def fmt(message, category, filename, lineno, line=None) -> str:  # noqa: ANN001 - warnings' own signature
        if category.__module__.startswith("gyrodenoise."):
            return f"warning: {message}\n"
        return plain(message, category, filename, lineno, line)

    warnings.formatwarning = fmt
    try:
        yield
    finally:
        warnings.formatwarning = plain


DEVICE_LINES = ("GPU available:", "TPU available:", "HPU available:", "IPU available:")


@contextlib.contextmanager
def device_lines_said() -> Iterator[None]:
    """Inside: Lightning's "GPU available: ..." lines of a second Trainer of the same run (training's scoring
    trainer), said already by the first, are not printed again."""
    log = logging.getLogger(LIGHTNING_LOGGER)
    drop = _DropNoise(DEVICE_LINES)
    log.addFilter(drop)
    try:
        yield
    finally:
        log.removeFilter(drop)


def lightning_lines_once() -> None:
    """Lightning's top package prints its records with a console handler of its own, while its subpackages also
    pass them to the root logger when that has handlers (a Hydra command's console and log file): every Lightning
    line came twice. Where the root logger handles records, Lightning's own console handler goes, so the job's
    logging config (hydra/job_logging) alone decides how they look."""
    if logging.getLogger().hasHandlers():
        top = logging.getLogger("lightning")
        for handler in [h for h in top.handlers if type(h) is logging.StreamHandler]:
            top.removeHandler(handler)


INTERRUPTED = "interrupted: no output of this run was left half-written"


def interrupt_in_one_line(main: Callable[..., int]) -> Callable[..., int]:
    """A command's `main` that Ctrl-C ends with one line and status 130 (the shell's for SIGINT), not a traceback:
    its outputs are written whole or not at all (`atomic`), so there is nothing more to say."""

    @functools.wraps(main)
    def wrapped(*args: Any, **kwargs: Any) -> int:
        try:
            return main(*args, **kwargs)
        except KeyboardInterrupt:
            print(INTERRUPTED, file=sys.stderr)
            return 130

    return wrapped
