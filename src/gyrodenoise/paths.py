"""Paths as written into reports, summaries and model metadata: portable, never the developer's machine.

Committed reports are read on other machines, so an absolute path such as /home/me/repo/outputs/... says
nothing there (and leaks the folder layout). Shipped models are named by their shipped name (see
gyrodenoise.pretrained); other paths are written relative to the working directory (the repository root
for the commands in the README and docs/) when they lie inside it or beside it, else under '~' when in the home
folder, else as given.
"""

from __future__ import annotations

import os
import re
import shlex
import sys
from collections.abc import Iterable, Sequence
from pathlib import Path


def portable_path(path: str | Path) -> str:
    """`path` for a report: 'outputs/x', '../shared/data/euroc', '~/.cache/...', or unchanged."""
    p = Path(path)
    if not p.is_absolute():
        return str(path)
    p = Path(os.path.abspath(p))  # normalise '..' without resolving symlinks (a linked data folder keeps its name)
    cwd = Path.cwd()
    if cwd.parent != cwd.parent.parent and p.is_relative_to(cwd.parent):  # inside the working directory or beside it
        return Path(os.path.relpath(p, cwd)).as_posix()
    home = Path.home()
    if p.is_relative_to(home):
        return "~/" + p.relative_to(home).as_posix()
    return str(path)


_SHELL_SAFE = re.compile(r"[\w./:=,+@%~-]*")


def portable_command(args: Iterable[str]) -> str:
    """A command line with each absolute path argument (also `key=/abs/path` overrides) made portable."""
    out = []
    for a in map(str, args):
        key, sep, value = a.rpartition("=") if "=" in a and not a.startswith("/") else ("", "", a)
        out.append(key + sep + portable_path(value) if value.startswith("/") else a)
    return " ".join(out)


def _shell_word(a: str) -> str:
    """`a` quoted where a shell would split or expand it (spaces, Hydra lists [a,b], $, quotes)."""
    return a if _SHELL_SAFE.fullmatch(a) else shlex.quote(a)


def invoked_command(module: str, argv: Sequence[str] | None = None) -> str:
    """The command line as the user typed it: `python -m gyrodenoise.<module> ...` when run as a module
    (sys.argv[0] is then the module's file), the console script's name otherwise; paths made portable."""
    argv = list(sys.argv if argv is None else argv)
    prog = Path(argv[0]).name if argv else module
    if prog.endswith(".py"):
        prog = f"python -m gyrodenoise.{module}"
    words = [_shell_word(portable_command([a])) for a in argv[1:]]  # the record re-runs as it is
    return " ".join([prog, *words])


def recorded_command(module: str) -> str:
    """What a run records as its command: the command line (`invoked_command`), or, when `gyrodenoise.<module>`'s
    function was called from Python (no Hydra run; sys.argv is then the caller's, a notebook kernel's say), the call."""
    from hydra.core.hydra_config import HydraConfig

    if HydraConfig.initialized():
        return invoked_command(module)
    return f"gyrodenoise.{module}.{module}(cfg) called from Python (cfg: the config recorded with the run)"


def portable_tree(obj: object) -> object:
    """`obj` (nested dicts / lists, e.g. a resolved config) with every absolute path string made portable."""
    if isinstance(obj, dict):
        return {k: portable_tree(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [portable_tree(v) for v in obj]
    return portable_path(obj) if isinstance(obj, str) and obj.startswith("/") else obj
