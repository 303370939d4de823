"""Where a result came from: the machine and the code version that results files record."""

from __future__ import annotations

import hashlib
import json
import os
import platform
import subprocess
from pathlib import Path

import torch


def machine_description() -> str:
    """Host, CPU, thread count, torch build and GPU, as summaries and benchmark tables print them."""
    cpu = platform.processor() or platform.machine()
    gpu = torch.cuda.get_device_name(0) if torch.cuda.is_available() else "no GPU"
    return f"{platform.node()} ({cpu}, {os.cpu_count()} CPU threads, torch {torch.__version__}, {gpu})"


def library_versions() -> dict[str, str]:
    """Python's version and the libraries a run's figures depend on, for summaries (a rerun that differs may owe it
    to one of them)."""
    from importlib.metadata import PackageNotFoundError, version

    out = {"python": platform.python_version()}
    for name in ("torch", "lightning", "numpy", "scipy", "hydra-core", "omegaconf"):
        try:
            out[name] = version(name)
        except PackageNotFoundError:
            continue
    return out


def file_sha256(path: str | Path) -> str:
    """The file's sha256 (hex), read in blocks."""
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def git_revision(repo: Path, scope: str | None = None, untracked: bool = False) -> tuple[str, bool] | None:
    """(short commit of HEAD, whether the work tree differs from it under `scope`, untracked files counted only
    if `untracked`) of the checkout at `repo`; None without git or outside a checkout."""
    status = ["git", "status", "--porcelain", f"--untracked-files={'normal' if untracked else 'no'}"]
    try:
        head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=repo, capture_output=True, text=True)
        dirty = subprocess.run(status + ([scope] if scope else []), cwd=repo, capture_output=True, text=True)
    except OSError:
        return None
    if head.returncode != 0:
        return None
    return head.stdout.strip(), bool(dirty.stdout.strip())


def code_version() -> dict:
    """The package version and, run from a checkout of this repository (src/gyrodenoise), its commit and whether
    src/ differs from it; an installed copy (`pip install .`), the commit its wheel was built from
    (gyrodenoise/_build_info.json, written by setup.py; `"built": true`). A git repository around site-packages (a
    .venv inside someone's project) is not this code's and is not asked."""
    import gyrodenoise

    out: dict = {"package": gyrodenoise.__version__}
    package = Path(gyrodenoise.__file__).resolve().parent
    repo = package.parents[1]
    # a new module under src/ changes the code as an edited one does: untracked files count
    if (repo / "pyproject.toml").is_file() and (rev := git_revision(repo, scope="src", untracked=True)) is not None:
        out["commit"], out["dirty"] = rev
    elif (info := package / "_build_info.json").is_file():
        built = json.loads(info.read_text(encoding="utf-8"))
        if built.get("commit"):
            out |= {"commit": built["commit"], "dirty": built.get("dirty"), "built": True}
    return out


def code_version_text() -> str:
    """`code_version()` in words: 'gyrodenoise <version>, commit <hash>[ with local changes in src/]' (the commit of a
    checkout, or of the wheel an installed copy was built from; the version only when neither is known)."""
    v = code_version()
    out = f"gyrodenoise {v['package']}"
    if "commit" not in v:
        return out
    if v.get("built"):
        return out + f", commit {v['commit']} (wheel)"
    return out + f", commit {v['commit']}" + (" with local changes in src/" if v.get("dirty") else "")
