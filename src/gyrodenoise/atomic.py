"""Atomic file output: write to a temporary file beside the target, then rename over it.

An interrupted run therefore never leaves a half-written file that looks whole.
"""

from __future__ import annotations

import errno
import json
import math
import os
import shutil
import tempfile
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def output_path_problem(path: str | Path, folder: bool = False) -> str | None:
    """Why `path` cannot be written (a file, or with `folder` a folder of outputs): it is a folder where a file is
    meant, a file where a folder is meant, a folder above it is a file, or the nearest folder that exists cannot be
    written (read-only, forbidden: a file is made there and removed to find out). None when it can be. The commands ask
    this before their work, so that a wrong output path is not found only when the results are written."""
    path = Path(path)
    if not folder and path.is_dir():
        return f"{path} is a folder: give a file path"
    if folder and path.exists() and not path.is_dir():
        return f"{path} is a file: give a folder"
    for above in (path, *path.parents) if folder else path.parents:
        if above.exists():
            if not above.is_dir():
                return f"{above} is a file, not a folder: {path} cannot be written under it"
            return _unwritable(above)
    return None


def _unwritable(folder: Path) -> str | None:
    """Why no file can be made in the existing `folder`, or None (os.access says yes to root on a read-only mount)."""
    try:
        fd, probe = tempfile.mkstemp(dir=folder, prefix=".write-check-")
    except OSError as e:
        return f"{folder} cannot be written ({e.strerror or e}): give a folder you can write to"
    os.close(fd)
    os.remove(probe)
    return None


def _make_parent(path: Path) -> None:
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except (FileExistsError, NotADirectoryError) as e:  # a folder on the way is a file: say which, not mkdir's errno
        raise NotADirectoryError(errno.ENOTDIR, output_path_problem(path) or str(e), str(path)) from None


@contextmanager
def atomic_path(path: str | Path, suffix: str = "") -> Iterator[Path]:
    """Yield a temporary path to write; it replaces `path` only if the block succeeds."""
    path = Path(path)
    _make_parent(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=suffix or ".tmp")
    os.close(fd)
    os.chmod(tmp, 0o666 & ~_umask())  # mkstemp creates 0600; give the result the usual permissions
    try:
        yield Path(tmp)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)


@contextmanager
def staged_outputs(folder: str | Path, marker: str, before_moving: Callable[[], None] | None = None) -> Iterator[Path]:
    """Yield a hidden folder inside `folder` to write a command's outputs into. When the block succeeds,
    `before_moving()` runs (e.g. removing an earlier run's outputs) and the staged files move into `folder`, `marker`
    (the sign of a finished run) last. When it fails, the staged files go, and so do `folder` and the folders above
    it that this made and that are left empty: a failed run leaves no outputs that look whole, and what was in
    `folder` before it (an earlier run's results, the user's files, the command's log) stays as it was."""
    folder = Path(folder)
    made = [p for p in (folder, *folder.parents) if not p.exists()]
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except (FileExistsError, NotADirectoryError) as e:
        raise NotADirectoryError(errno.ENOTDIR, output_path_problem(folder, True) or str(e), str(folder)) from None
    stage = Path(tempfile.mkdtemp(dir=folder, prefix=".unfinished-"))
    done = False
    try:
        yield stage
        if before_moving is not None:
            before_moving()
        files = sorted(
            (p.relative_to(stage) for p in stage.rglob("*") if p.is_file()), key=lambda p: (p == Path(marker), str(p))
        )
        for f in files:
            (folder / f).parent.mkdir(parents=True, exist_ok=True)
            os.replace(stage / f, folder / f)
        done = True
    finally:
        shutil.rmtree(stage, ignore_errors=True)
        if not done:
            for p in made:  # deepest first
                try:
                    p.rmdir()
                except OSError:  # holds something: the command's log, say
                    break


def write_text(path: str | Path, text: str) -> Path:
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return Path(path)


def write_bytes(path: str | Path, data: bytes) -> Path:
    with atomic_path(path, Path(path).suffix) as tmp:
        tmp.write_bytes(data)
    return Path(path)


def jsonable(x: object) -> object:
    """`x` with numpy and torch numbers as Python numbers and NaN / inf as None (null): JSON has no NaN, and
    tools other than Python's json (jq, JavaScript) refuse the `NaN` token."""
    if isinstance(x, dict):
        return {str(k): jsonable(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [jsonable(v) for v in x]
    if hasattr(x, "tolist") and not isinstance(x, str):  # numpy arrays and scalars, torch tensors
        return jsonable(x.tolist())
    if isinstance(x, float):
        return x if math.isfinite(x) else None
    return x


def write_json(path: str | Path, data: dict) -> Path:
    """`data` as strict JSON (NaN / inf written as null), atomically."""
    return write_text(path, json.dumps(jsonable(data), indent=2, allow_nan=False) + "\n")


def read_marker(path: str | Path) -> dict | None:
    """An earlier run's finished-run marker (its JSON summary): None where there is none, {} where it is not a JSON
    object (another program's file: it is replaced all the same)."""
    path = Path(path)
    if not path.is_file():
        return None
    try:
        earlier = json.loads(path.read_text())
    except ValueError:
        return {}
    return earlier if isinstance(earlier, dict) else {}


def remove_earlier_outputs(folder: str | Path, marker: str, patterns: tuple[str, ...]) -> dict | None:
    """Before a command writes into `folder`: remove what an earlier run of it wrote there, so that a rerun (other
    inputs, fewer figures) leaves none of the earlier files beside its own. `marker` (written last, the sign of a
    finished run) goes first, then every file matching `patterns` (globs relative to `folder`); files of the
    user's and folders that still hold them stay. Returns the earlier marker's JSON (for a note), else None."""
    folder = Path(folder)
    earlier = read_marker(folder / marker)
    (folder / marker).unlink(missing_ok=True)
    stale = [f for pattern in patterns for f in folder.glob(pattern) if f.is_file()]
    for f in stale:
        f.unlink(missing_ok=True)
    for parent in sorted({f.parent for f in stale} - {folder}, key=lambda p: -len(p.parts)):
        for up in [parent, *parent.parents]:  # the emptied folders below `folder`, deepest first
            if up == folder or folder not in up.parents:
                break
            try:
                up.rmdir()
            except OSError:  # kept when it holds files of the user's
                break
    return earlier
