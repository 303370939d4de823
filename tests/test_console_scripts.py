"""The installed console scripts (pyproject [project.scripts]) start like `python -m gyrodenoise.<module>`.

A console script calls `main` from a module that is not `__main__`, so Hydra looks for the configs as the
package `gyrodenoise.conf` rather than next to the file: a layout that only works with `python -m` fails there.
"""

from __future__ import annotations

import subprocess
import sys

import pytest


@pytest.mark.parametrize("module", ["train", "evaluate", "fit_calibrated"])
def test_hydra_entry_points_start_when_called_as_a_console_script(module, tmp_path):
    code = f"import sys; from gyrodenoise.{module} import main; sys.argv = ['gyrodenoise-{module}', '--help']; main()"
    run = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr[-2000:]
    assert "Configuration groups" in run.stdout and "dataset:" in run.stdout
