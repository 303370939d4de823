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
    assert "Configuration group" in run.stdout and "dataset" in run.stdout
    assert run.stdout.startswith(f"python -m gyrodenoise.{module} ")  # its own help, not the training one
    if module != "evaluate":  # a help page, not Hydra's dump of the ~240-line training config
        assert len(run.stdout.splitlines()) < 40 and "retain_freed_memory" not in run.stdout
    if module == "evaluate":  # it composes the dataset group only: its help names every dataset, no training group
        from gyrodenoise.config import CONF_DIR

        listed = run.stdout.split("dataset=", 1)[1].split()[0].split("|")
        assert sorted(listed) == sorted(f.stem for f in (CONF_DIR / "dataset").glob("*.yaml"))
        assert "model: calibrated" not in run.stdout and "trainer: " not in run.stdout
