"""Committed reports and results are read on other machines: no absolute path of a development machine in them."""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

from conftest import REPO

from gyrodenoise.paths import portable_command, portable_path, portable_tree
from gyrodenoise.pretrained import load_model, model_name, shipped_dir

# home folders and this project's development root; a leading '~', '.' or word character means a relative path
ABSOLUTE_DEV_PATH = re.compile(r"(?<![\w.~/-])/(?:work|home|root|Users)/|\b[A-Za-z]:\\Users\\")
CHECKED = ("reports", "benchmarks/results", "src/gyrodenoise/weights")


def committed_text_files() -> list[Path]:
    """Tracked files under CHECKED (every file there when this is not a git checkout), text ones only."""
    if shutil.which("git") and (REPO / ".git").exists():
        names = subprocess.run(
            ["git", "ls-files", "-z", "--", *CHECKED], cwd=REPO, capture_output=True, check=True
        ).stdout.decode()
        paths = [REPO / n for n in names.split("\0") if n]
    else:
        paths = [p for d in CHECKED for p in (REPO / d).rglob("*") if p.is_file()]
    texts = []
    for p in paths:
        head = p.read_bytes()[:4096]
        if b"\0" not in head:  # figures and weights are binary
            texts.append(p)
    return texts


def test_no_absolute_development_paths_in_committed_files():
    files = committed_text_files()
    assert len(files) > 10 and any(p.suffix == ".json" for p in files)  # the scan found the reports
    hits = []
    for p in files:
        for lineno, line in enumerate(p.read_text(encoding="utf-8", errors="replace").splitlines(), start=1):
            if m := ABSOLUTE_DEV_PATH.search(line):
                hits.append(f"{p.relative_to(REPO)}:{lineno}: ...{line[max(0, m.start() - 30) : m.end() + 50]}...")
    assert not hits, "absolute paths of a development machine (name shipped models by name):\n" + "\n".join(hits)


def test_pattern_catches_what_it_should():
    bad = ['"model": "/work/main/src/x.pt"', "--root /root/.cache/x", "/home/me/x", r"C:\Users\me\x"]
    ok = ["--root ~/.cache/x", "../shared/data/euroc", "GYRODENOISE_CACHE=/tmp/fresh", "https://host/home/x"]
    assert all(ABSOLUTE_DEV_PATH.search(s) for s in bad)
    assert not any(ABSOLUTE_DEV_PATH.search(s) for s in ok)


def test_paths_written_portably(tmp_path, monkeypatch):
    work = tmp_path / "repo"
    work.mkdir()
    monkeypatch.chdir(work)
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert portable_path(work / "outputs" / "a.ckpt") == "outputs/a.ckpt"
    assert portable_path(tmp_path / "shared" / "data") == "../shared/data"
    assert portable_command(["--root", str(work / "d"), f"dataset.root={tmp_path / 'shared'}", "x=[a,b]"]) == (
        "--root d dataset.root=../shared x=[a,b]"
    )
    cfg = {"paths": {"output_dir": str(work / "runs" / "a")}, "cbs": [{"dirpath": str(work / "c")}], "lr": 0.01}
    assert portable_tree(cfg) == {"paths": {"output_dir": "runs/a"}, "cbs": [{"dirpath": "c"}], "lr": 0.01}
    assert model_name(shipped_dir() / "euroc.pt") == "euroc"
    if (shipped_dir() / "euroc.pt").is_file():
        assert load_model("euroc")[1]["name"] == "euroc"


def test_home_paths_use_tilde(tmp_path, monkeypatch):
    monkeypatch.chdir("/")  # neither inside nor beside the working directory
    monkeypatch.setenv("HOME", str(tmp_path))
    assert portable_path(tmp_path / ".cache" / "sim-1") == "~/.cache/sim-1"
    assert portable_path("/opt/data") == "/opt/data"  # elsewhere: unchanged


def test_every_benchmark_script_answers_help_instead_of_running():
    """`python benchmarks/NAME.py --help` shows its options (benchmarks/README.md); a script without a parser ran
    instead, and some write committed files (ship_tumvi.py the shipped tumvi model)."""
    scripts = [p for p in (REPO / "benchmarks").glob("*.py") if '__name__ == "__main__"' in p.read_text()]
    assert len(scripts) > 40
    silent = [p.name for p in scripts if "argparse.ArgumentParser(" not in p.read_text()]
    assert not silent, f"no argument parser: {silent}"
