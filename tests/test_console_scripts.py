"""The installed console scripts (pyproject [project.scripts]) start like `python -m gyrodenoise.<module>`.

A console script calls `main` from a module that is not `__main__`, so Hydra looks for the configs as the
package `gyrodenoise.conf` rather than next to the file: a layout that only works with `python -m` fails there.
"""

from __future__ import annotations

import os
import subprocess
import sys

import pytest


@pytest.mark.parametrize("module", ["train", "evaluate", "fit_calibrated"])
def test_hydra_entry_points_start_when_called_as_a_console_script(module, tmp_path):
    code = f"import sys; from gyrodenoise.{module} import main; sys.argv = ['gyrodenoise-{module}', '--help']; main()"
    run = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr[-2000:]
    assert "Configuration group" in run.stdout and "dataset" in run.stdout
    assert run.stdout.startswith(f"python -m gyrodenoise.{module} ")  # its own help, not the training one
    if module != "evaluate":  # a help page, not Hydra's dump of the ~240-line training config
        assert len(run.stdout.splitlines()) < 40 and "retain_freed_memory" not in run.stdout
    if module == "evaluate":  # it composes the dataset group only: its help names every dataset, no training group
        from gyrodenoise.config import CONF_DIR

        listed = run.stdout.split("dataset=", 1)[1].split()[0].split("|")
        assert sorted(listed) == sorted(f.stem for f in (CONF_DIR / "dataset").glob("*.yaml"))
        assert "model: calibrated" not in run.stdout and "trainer: " not in run.stdout


# ---------------------------------------------------------------- Ctrl-C while a command starts (gyrodenoise.launch)
CTRL_C_AT_IMPORT = '''
import os, signal, sys, time

class CtrlCWhileImporting:
    """Ctrl-C pressed while {module} is being imported: a real SIGINT to this process, at that moment."""

    def find_spec(self, name, path=None, target=None):
        if name == {module!r}:
            sys.meta_path.remove(self)
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(30)  # the signal's KeyboardInterrupt is raised in here
        return None

sys.meta_path.insert(0, CtrlCWhileImporting())
'''


def _started_and_interrupted(tmp_path, args: list[str], hooked: str = "torch") -> subprocess.CompletedProcess:
    """`python ARGS` with a SIGINT sent while `hooked` is imported (a sitecustomize on PYTHONPATH sets it up, so that
    `python -m` runs as a user's would); --help in ARGS: a start that is not interrupted ends at once."""
    hook = tmp_path / "hook"
    hook.mkdir(exist_ok=True)
    (hook / "sitecustomize.py").write_text(CTRL_C_AT_IMPORT.format(module=hooked))
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(hook), *sys.path])}
    env.pop("HYDRA_FULL_ERROR", None)
    return subprocess.run([sys.executable, *args], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120)


@pytest.mark.parametrize("module", ["train", "evaluate", "correct"])
def test_ctrl_c_while_a_command_starts_is_one_line_and_status_130(module, tmp_path):
    """A Ctrl-C in the first seconds (the command's module importing torch) escaped before `main`, whose handling
    says it in one line, and printed a traceback: the console script (gyrodenoise.launch) and `python -m` say
    `gyrodenoise-<module>: interrupted while starting, before any work` and exit with 130."""
    script = f"import sys; from gyrodenoise.launch import {module}; sys.argv = ['gyrodenoise-{module}', '--help']; "
    for args in (["-c", script + f"sys.exit({module}())"], ["-m", f"gyrodenoise.{module}", "--help"]):
        run = _started_and_interrupted(tmp_path, args)
        assert (run.returncode, run.stdout) == (130, ""), (args, run.stderr[-2000:])
        assert run.stderr == f"gyrodenoise-{module}: interrupted while starting, before any work\n", args


@pytest.mark.parametrize(
    "command, hooked",
    [
        ("export", "torch"),
        ("ensemble", "torch"),
        ("shipped", "torch"),
        ("discrepancy", "numpy"),
        ("discrepancy.splits", "numpy"),
    ],
)
def test_ctrl_c_while_a_python_m_command_starts_is_one_line_and_status_130(command, hooked, tmp_path):
    """The `python -m` commands without a console script import torch or numpy at their top too: a Ctrl-C there
    printed KeyboardInterrupt's traceback from the import, before their `main`. They hand over to gyrodenoise.launch
    as train does, and their line names the command as typed; uninterrupted, --help is as before."""
    run = _started_and_interrupted(tmp_path, ["-m", f"gyrodenoise.{command}", "--help"], hooked)
    assert (run.returncode, run.stdout) == (130, ""), run.stderr[-2000:]
    assert run.stderr == f"python -m gyrodenoise.{command}: interrupted while starting, before any work\n"
    plain = subprocess.run(
        [sys.executable, "-m", f"gyrodenoise.{command}", "--help"], cwd=tmp_path, capture_output=True, text=True,
        timeout=120,
    )  # fmt: skip
    assert plain.returncode == 0 and f"python -m gyrodenoise.{command}" in plain.stdout, plain.stderr[-2000:]


def test_console_scripts_point_to_the_launcher():
    tomllib = pytest.importorskip("tomllib")
    from pathlib import Path

    import gyrodenoise.launch as launch

    scripts = tomllib.loads((Path(__file__).parents[1] / "pyproject.toml").read_text())["project"]["scripts"]
    assert scripts == {f"gyrodenoise-{m}": f"gyrodenoise.launch:{m}" for m in ("train", "evaluate", "correct")}
    assert all(callable(getattr(launch, m)) for m in ("train", "evaluate", "correct"))


def test_ctrl_c_on_the_way_into_the_work_is_one_line_and_hydra_full_error_keeps_the_trace(monkeypatch, capsys):
    """A KeyboardInterrupt out of `main` (Hydra composing the config, before the command's own handling) ends in one
    line too; HYDRA_FULL_ERROR=1, Hydra's switch for a full trace, lets it through as `user_errors` does."""
    import types

    import gyrodenoise.launch as launch

    def main():
        raise KeyboardInterrupt

    monkeypatch.setattr(launch.importlib, "import_module", lambda name: types.SimpleNamespace(main=main))
    monkeypatch.delenv("HYDRA_FULL_ERROR", raising=False)
    with pytest.raises(SystemExit) as stop:
        launch.train()
    assert stop.value.code == 130 and capsys.readouterr().err == "gyrodenoise-train: interrupted\n"
    monkeypatch.setenv("HYDRA_FULL_ERROR", "1")
    with pytest.raises(KeyboardInterrupt):
        launch.evaluate()
    # a main that returns: its value is the exit status, as the console script's sys.exit(main()) had it
    monkeypatch.setattr(launch.importlib, "import_module", lambda name: types.SimpleNamespace(main=lambda: 2))
    assert launch.correct() == 2
    with pytest.raises(SystemExit) as stop:
        launch.run_as_main("correct")
    assert stop.value.code == 2


def test_importing_the_commands_installs_no_hook():
    """The one-line Ctrl-C is the commands' own: importing them from Python changes no excepthook or handler."""
    code = (
        "import signal, sys; before = signal.getsignal(signal.SIGINT); "
        "import gyrodenoise.launch, gyrodenoise.train, gyrodenoise.evaluate, gyrodenoise.correct; "
        "assert sys.excepthook is sys.__excepthook__ and signal.getsignal(signal.SIGINT) is before; "
        "assert gyrodenoise.train.__name__ == 'gyrodenoise.train'"
    )
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr[-2000:]
