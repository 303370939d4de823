"""Where a result came from: the machine and the code version that results files record."""

from __future__ import annotations

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
