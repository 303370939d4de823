"""The console scripts' entry points (pyproject [project.scripts]), and `python -m` of the same commands.

train, evaluate and correct import torch, Hydra and numpy at their top (~3 s): a Ctrl-C in that time raised
KeyboardInterrupt out of the import, before their `main` and its one-line handling of Ctrl-C
(`notices.interrupt_in_one_line`, `cli_errors.user_errors`) could run, and printed a traceback. These functions
import the command's module inside a try: an interrupted start prints one line (`gyrodenoise-train: interrupted
while starting, before any work`) and exits with 130, the shell's status for SIGINT. HYDRA_FULL_ERROR=1 (Hydra's
switch for full traces, which `user_errors` honours for Ctrl-C too) shows the traceback as before.

`python -m gyrodenoise.train` (evaluate, correct) comes here as well: the module's first lines hand over to
`run_as_main` before its own imports when it runs as `__main__`. So do the commands that are `python -m` only and
import torch or numpy at their top (`PYTHON_M`: export, ensemble, shipped, discrepancy, discrepancy.splits); their
line names the command as it was typed (`python -m gyrodenoise.export: interrupted while starting, before any work`).
Nothing is installed at import: `import gyrodenoise.train` from Python leaves sys.excepthook and the signal handlers
as they were. This module imports the standard library only (a console script loads it first).
"""

from __future__ import annotations

import importlib
import os
import sys
from typing import Any


def _interrupted(prog: str, when: str) -> SystemExit:
    print(f"{prog}: interrupted{when}", file=sys.stderr)
    return SystemExit(130)


# the `python -m` commands without a console script that come here: module (as imported) -> how the command is typed
PYTHON_M = {
    "export": "python -m gyrodenoise.export",
    "ensemble": "python -m gyrodenoise.ensemble",
    "shipped": "python -m gyrodenoise.shipped",
    "discrepancy.__main__": "python -m gyrodenoise.discrepancy",
    "discrepancy.splits": "python -m gyrodenoise.discrepancy.splits",
}


def run(module: str) -> Any:
    """`gyrodenoise.<module>.main()`, its module imported here; a Ctrl-C while importing it or on the way into its
    work (Hydra composing the config, outside the command's own handling) ends with one line and status 130."""
    prog = PYTHON_M.get(module, f"gyrodenoise-{module}")
    full = os.environ.get("HYDRA_FULL_ERROR") == "1"
    try:
        main = importlib.import_module(f"gyrodenoise.{module}").main
    except KeyboardInterrupt:
        if full:
            raise
        raise _interrupted(prog, " while starting, before any work") from None
    try:
        return main()
    except KeyboardInterrupt:  # inside its work each command says it in its own line; this is around that
        if full:
            raise
        raise _interrupted(prog, "") from None


def run_as_main(module: str) -> None:
    """`python -m gyrodenoise.<module>`: called by that module's first lines when it runs as `__main__`; imports it
    again as `gyrodenoise.<module>` (as a console script does) and exits with its `main`'s status."""
    raise SystemExit(run(module))


def train() -> Any:
    return run("train")


def evaluate() -> Any:
    return run("evaluate")


def correct() -> Any:
    return run("correct")
