"""Build hook only (the project is described in pyproject.toml): a wheel records the commit it was built from.

`pip install .` copies the package into site-packages, where no git checkout says which code it is; training runs
record `code_version` in summary.json, and without this an installed copy recorded only "0.1.0" for every commit.
The build writes gyrodenoise/_build_info.json ({"commit", "dirty"} of the source checkout, null outside one).
"""

import json
import subprocess
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py


def _git(*args: str) -> str | None:
    try:
        run = subprocess.run(["git", *args], capture_output=True, text=True, cwd=Path(__file__).parent, timeout=30)
    except (OSError, subprocess.TimeoutExpired):
        return None
    return run.stdout.strip() if run.returncode == 0 else None


class BuildPyWithCommit(build_py):
    def run(self) -> None:
        super().run()
        commit = _git("rev-parse", "--short", "HEAD")
        dirty = None if commit is None else bool(_git("status", "--porcelain", "--untracked-files=no", "src"))
        target = Path(self.build_lib) / "gyrodenoise" / "_build_info.json"
        target.write_text(json.dumps({"commit": commit, "dirty": dirty}) + "\n", encoding="utf-8")


setup(cmdclass={"build_py": BuildPyWithCommit})
