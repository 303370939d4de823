"""The code version that results files record: the commit, and whether the work tree differed from it."""

import shutil
import subprocess

import pytest

from gyrodenoise.provenance import git_revision, machine_description

pytestmark = pytest.mark.skipif(shutil.which("git") is None, reason="git is not installed")


def _git(repo, *args):
    identity = ["-c", "user.name=t", "-c", "user.email=t@t"]
    subprocess.run(["git", *identity, *args], cwd=repo, check=True, capture_output=True)


def test_commit_and_changes_by_scope(tmp_path):
    assert git_revision(tmp_path) is None  # not a checkout
    _git(tmp_path, "init", "-q")
    (tmp_path / "src").mkdir()
    (tmp_path / "src" / "a.py").write_text("x = 1\n")
    (tmp_path / "notes.md").write_text("n\n")
    _git(tmp_path, "add", ".")
    _git(tmp_path, "commit", "-qm", "c")
    head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=tmp_path, capture_output=True, text=True)
    assert git_revision(tmp_path) == (head.stdout.strip(), False)
    (tmp_path / "src" / "new.py").write_text("")  # untracked: counted only when asked
    assert git_revision(tmp_path, scope="src")[1] is False
    assert git_revision(tmp_path, scope="src", untracked=True)[1] is True
    (tmp_path / "notes.md").write_text("changed\n")  # tracked change outside the scope
    assert git_revision(tmp_path)[1] is True
    assert git_revision(tmp_path, scope="src")[1] is False


def test_machine_description_names_torch():
    assert "torch " in machine_description() and "CPU threads" in machine_description()
