"""Load sequences through a preprocessing cache keyed by the source files' content, the settings and the readers' code.

A changed data file, setting or reader gives a new key and so a rebuild; files are written atomically
(temporary file + rename), so an interrupted run never leaves a cache file that looks whole.
"""

from __future__ import annotations

import functools
import hashlib
import importlib
import json
import os
import warnings
import zipfile
from pathlib import Path

import numpy as np

from gyrodenoise.atomic import atomic_path
from gyrodenoise.data.readers import DataFormatWarning, find_groundtruth_file, read_groundtruth, read_imu
from gyrodenoise.data.sequence import Sequence, build_sequence, sequence_folder

CACHE_VERSION = 2  # this module's layout of a cache file; 2: the reader warnings kept in meta (read_warnings)
# the modules whose code decides what a cached sequence holds: read_imu, read_groundtruth, build_sequence and what
# they import of this package. Their source is in the key (`reader_digest`): a sequence cached before a reader
# changed (a check added, a column read otherwise) was served as the old code had read it. tests/test_damaged_inputs
# checks that the list holds every module they import.
READER_MODULES = ("gyrodenoise.data.readers", "gyrodenoise.data.asl_header", "gyrodenoise.data.sequence")
# a sequence's meta key: the reader's warnings about its files (a repeated line kept once, a last line without a
# line break), replayed whenever the sequence is loaded from the cache: the files still have what they warned of
READ_WARNINGS = "read_warnings"
_ARRAYS = ("t", "gyro", "acc", "rot", "pos", "gt_mask")


def default_cache_dir() -> Path:
    return Path(os.environ.get("GYRODENOISE_CACHE", Path.home() / ".cache" / "gyrodenoise"))


def _file_digest(path: Path) -> str:
    h = hashlib.sha1()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


@functools.cache  # ~40 kB read once per process
def reader_digest() -> str:
    """sha1 of the source of `READER_MODULES`: it changes whenever the readers' code does, with nothing to bump."""
    h = hashlib.sha1()
    for name in READER_MODULES:
        h.update(Path(importlib.import_module(name).__file__).read_bytes())
    return h.hexdigest()


def cache_key(files: list[Path], settings: dict) -> str:
    h = hashlib.sha1()
    key = {"v": CACHE_VERSION, "readers": reader_digest(), "settings": settings}
    h.update(json.dumps(key, sort_keys=True).encode())
    for f in files:
        h.update(_file_digest(f).encode())
    return h.hexdigest()[:16]


def atomic_save_npz(path: Path, **arrays: np.ndarray) -> None:
    with atomic_path(path, suffix=".npz") as tmp:  # np.savez appends .npz to other names
        np.savez(tmp, **arrays)


def missing_groundtruth_message(mav0: Path, name: str, gt_file: str) -> str:
    """What to do when the ground-truth file a dataset config names for a sequence is not there."""
    from gyrodenoise.data.fetch import extra_file_source

    gt_path, root = mav0 / gt_file, mav0.parent.parent
    url = extra_file_source(root.name, name, f"mav0/{gt_file}")  # known for the dataset's own folder name
    get = (
        f"`python -m gyrodenoise.data.fetch {root.name} --dest {root} --sequences {name}` downloads it "
        f"(from {url}), or put it there by hand; "
        if url
        else ""
    )
    return (
        f"{gt_path}: ground-truth file not found; the dataset config names it for {name} (dataset.gt_files). "
        f"{get}to use the sequence's standard ground truth instead, drop the entry: '~dataset.gt_files.{name}' "
        f"(and '~dataset.eval_gt_variants.{name}' where the config lists one)."
    )


def load_sequence(
    root: str | Path,
    name: str,
    gt_file: str | None = None,
    max_gap_factor: float = 3.0,
    cache_dir: str | Path | None = None,
) -> Sequence:
    """Read <root>/<name>/mav0 (IMU + ground truth), through the cache.

    gt_file: ground-truth file relative to mav0 (default: the dataset's standard one).
    cache_dir: None uses $GYRODENOISE_CACHE or ~/.cache/gyrodenoise; "" disables the cache.
    """
    mav0 = sequence_folder(root, name)
    imu_path = mav0 / "imu0" / "data.csv"
    gt_path = mav0 / gt_file if gt_file else find_groundtruth_file(mav0)
    if not gt_path.is_file():
        raise FileNotFoundError(missing_groundtruth_message(mav0, name, gt_file))
    if not imu_path.is_file():
        raise FileNotFoundError(f"{imu_path}: IMU file not found (ASL layout mav0/imu0/data.csv).")
    settings = {"max_gap_factor": max_gap_factor, "name": name}
    use_cache = cache_dir != ""
    cache_path = None
    if use_cache:
        key = cache_key([imu_path, gt_path], settings)
        cache_path = Path(cache_dir or default_cache_dir()) / f"{name}-{key}.npz"
        if cache_path.is_file():
            try:  # only the reading: an error of the sequence itself is not a damaged file
                with np.load(cache_path, allow_pickle=False) as z:
                    # the files this call read, not those of the run that filled the cache (same content,
                    # perhaps another root: reports and data-check messages name them)
                    meta = {**json.loads(str(z["meta"])), "imu_file": str(imu_path), "gt_file": str(gt_path)}
                    seq = Sequence(name=name, t0_ns=int(z["t0_ns"]), meta=meta, **{k: z[k] for k in _ARRAYS})
            except (OSError, EOFError, KeyError, ValueError, zipfile.BadZipFile) as e:  # damaged on disk: rebuild
                warnings.warn(f"{cache_path}: unreadable cache file ({e}); rebuilt from {mav0}", stacklevel=2)
            else:
                for message in seq.meta.get(READ_WARNINGS, []):  # what reading the files said, said again
                    warnings.warn(DataFormatWarning(message), stacklevel=2)
                return seq.from_first_ground_truth()
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always", DataFormatWarning)
        seq = build_sequence(name, read_imu(imu_path), read_groundtruth(gt_path), max_gap_factor)
    for w in said:  # passed on as they came; the reader's own are kept for the runs that load from the cache
        warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    seq.meta[READ_WARNINGS] = [str(w.message) for w in said if issubclass(w.category, DataFormatWarning)]
    if cache_path is not None:
        try:
            atomic_save_npz(
                cache_path,
                t0_ns=np.int64(seq.t0_ns),
                meta=np.array(json.dumps(seq.meta)),
                **{k: getattr(seq, k) for k in _ARRAYS},
            )
        except OSError as e:  # a full or read-only cache disk: the cache only saves time, the run goes on
            warnings.warn(
                f"{cache_path}: cannot write the cache ({e.strerror or e}); going on without it (GYRODENOISE_CACHE "
                "sets its folder)",
                stacklevel=2,
            )
    return seq.from_first_ground_truth()
