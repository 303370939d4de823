"""Download EuRoC or TUM-VI and keep only the IMU and the ground truth, in the ASL layout the loaders read.

    python -m gyrodenoise.data.fetch euroc --dest data/euroc
    python -m gyrodenoise.data.fetch tumvi --dest data/tumvi --sequences dataset-room1_512_16
    python -m gyrodenoise.data.fetch euroc --dest data/euroc --base-url https://my.mirror/euroc

Result: <dest>/<sequence>/mav0/imu0/data.csv and the ground truth
(mav0/state_groundtruth_estimate0/ for EuRoC, mav0/mocap0/ for TUM-VI), with their sensor.yaml.
Images are never written. Downloads resume (HTTP Range) after an interruption, show a progress
bar, and are checked against a pinned checksum (CHECKSUMS below) or the server's md5 file where
the dataset publishes one (TUM-VI); the archive is deleted after extraction unless --keep-archives.
The datasets are licensed by their authors for research; see their pages before use.
"""

from __future__ import annotations

import argparse
import hashlib
import http.client
import os
import shutil
import sys
import tarfile
import time
import urllib.error
import urllib.request
import zipfile
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath

from tqdm import tqdm

from gyrodenoise.atomic import atomic_path

CHUNK = 1 << 20
RETRIES = 5


@dataclass(frozen=True)
class Dataset:
    base_url: str
    archives: dict[str, str]  # sequence -> archive path relative to base_url
    keep: tuple[str, ...]  # folders under mav0/ to keep
    md5_files: bool = False  # the server publishes <archive stem>.md5 beside each archive
    info: str = ""
    # sequence -> {path under the sequence folder: URL}: files the loaders' configs name that the archive lacks
    extra_files: dict[str, dict[str, str]] = field(default_factory=dict)


def _euroc(seq: str) -> str:
    group = {"MH": "machine_hall", "V1": "vicon_room1", "V2": "vicon_room2"}[seq[:2]]
    return f"{group}/{seq}/{seq}.zip"


EUROC_SEQUENCES = [
    "MH_01_easy", "MH_02_easy", "MH_03_medium", "MH_04_difficult", "MH_05_difficult",
    "V1_01_easy", "V1_02_medium", "V1_03_difficult", "V2_01_easy", "V2_02_medium", "V2_03_difficult",
]  # fmt: skip

DATASETS: dict[str, Dataset] = {
    "euroc": Dataset(
        base_url="http://robotics.ethz.ch/~asl-datasets/ijrr_euroc_mav_dataset",
        archives={s: _euroc(s) for s in EUROC_SEQUENCES},
        keep=("imu0", "state_groundtruth_estimate0"),
        # V1_01_easy's released orientation is ~5 deg off; dataset=euroc scores it against OpenVINS's recomputation
        extra_files={
            "V1_01_easy": {
                "mav0/state_groundtruth_estimate0/data_recomputed_openvins.csv": (
                    "https://raw.githubusercontent.com/rpng/open_vins/master/ov_data/euroc_mav/V1_01_easy.csv"
                )
            }
        },
        info="EuRoC MAV (ETH Zurich), ASL zip per sequence. The files now live in the ETH Research "
        "Collection too; point --base-url at any mirror with the <group>/<SEQ>/<SEQ>.zip layout.",
    ),
    "tumvi": Dataset(
        base_url="https://cdn3.vision.in.tum.de/tumvi/exported/euroc/512_16",
        archives={f"dataset-room{i}_512_16": f"dataset-room{i}_512_16.tar" for i in range(1, 7)},
        keep=("imu0", "mocap0"),
        md5_files=True,
        info="TUM-VI (TU Munich), room sequences, EuRoC-format export at 512x512.",
    ),
}

# Pinned checksums "sha256:<hex>" or "md5:<hex>" by archive file name, checked when present. Fill
# them from a verified download; without one (and without a server md5 file) the download is
# accepted after a warning and its sha256 is printed so it can be pinned here.
CHECKSUMS: dict[str, str] = {}


class FetchError(RuntimeError):
    """A download or an archive failed; the message says which and what to do."""


# ---------------------------------------------------------------- download


def _total_from(resp, offset: int) -> int | None:
    cr = resp.headers.get("Content-Range")  # bytes a-b/total
    if cr and "/" in cr and not cr.endswith("*"):
        return int(cr.rsplit("/", 1)[1])
    cl = resp.headers.get("Content-Length")
    return int(cl) + offset if cl is not None else None


def download(url: str, dest: Path, progress: bool = True, timeout: float = 60.0) -> Path:
    """Download to `dest`, resuming from `dest`.part; retries on interruptions with a Range request."""
    part = dest.with_name(dest.name + ".part")
    dest.parent.mkdir(parents=True, exist_ok=True)
    for attempt in range(RETRIES):
        offset = part.stat().st_size if part.exists() else 0
        req = urllib.request.Request(url, headers={"Range": f"bytes={offset}-"} if offset else {})
        try:
            with urllib.request.urlopen(req, timeout=timeout) as resp:
                if offset and resp.status != 206:  # the server ignored the range: start again
                    offset = 0
                total = _total_from(resp, offset)
                with (
                    open(part, "ab" if offset else "wb") as fh,
                    tqdm(
                        total=total,
                        initial=offset,
                        unit="B",
                        unit_scale=True,
                        unit_divisor=1024,
                        desc=dest.name,
                        disable=not progress,
                        leave=False,
                    ) as bar,
                ):
                    while chunk := resp.read(CHUNK):
                        fh.write(chunk)
                        bar.update(len(chunk))
        except urllib.error.HTTPError as e:
            if e.code == 416 and offset:  # nothing left to send: the .part is whole
                total = offset
            elif e.code in (404, 403, 401, 410):
                raise FetchError(
                    f"{url}: HTTP {e.code}. The server no longer serves this file there; pass "
                    "--base-url with a mirror that has the same layout."
                ) from None
            else:
                _wait(attempt, f"{url}: HTTP {e.code}")
                continue
        except (urllib.error.URLError, OSError, http.client.HTTPException) as e:  # lost / refused / reset
            _wait(attempt, f"{url}: {e}")
            continue
        size = part.stat().st_size
        if total is None or size == total:
            os.replace(part, dest)
            return dest
        if size > total:
            part.unlink()  # a corrupt partial file: start from scratch
        _wait(attempt, f"{url}: got {size} of {total} bytes")
    raise FetchError(
        f"{url}: download failed after {RETRIES} attempts; run the same command again to resume from {part}."
    )


def _wait(attempt: int, why: str) -> None:
    print(f"{why}; retrying ({attempt + 1}/{RETRIES})", file=sys.stderr)
    time.sleep(min(0.2 * 2**attempt, 5.0))


def file_digest(path: Path, algo: str) -> str:
    h = hashlib.new(algo)
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(CHUNK), b""):
            h.update(chunk)
    return h.hexdigest()


def expected_checksum(ds: Dataset, base_url: str, archive: str) -> str | None:
    """'algo:hex' from the pinned table, else from the server's md5 file, else None."""
    name = PurePosixPath(archive).name
    if name in CHECKSUMS:
        return CHECKSUMS[name]
    if not ds.md5_files:
        return None
    url = f"{base_url}/{PurePosixPath(archive).with_suffix('.md5')}"
    try:
        with urllib.request.urlopen(url, timeout=30) as resp:
            text = resp.read().decode("utf-8", "replace")
    except (urllib.error.URLError, OSError):
        return None
    for line in text.splitlines():  # md5sum format: '<hex>  <file name>'
        parts = line.split()
        if parts and len(parts[0]) == 32 and (len(parts) == 1 or parts[-1].lstrip("*") == name):
            return f"md5:{parts[0].lower()}"
    return None


def verify(path: Path, expected: str | None) -> str:
    """Check `path` against 'algo:hex'; returns its sha256 (for pinning)."""
    sha = file_digest(path, "sha256")
    if expected is None:
        print(f"warning: no checksum known for {path.name}; sha256 {sha} (pin it in CHECKSUMS)", file=sys.stderr)
        return sha
    algo, _, want = expected.partition(":")
    got = sha if algo == "sha256" else file_digest(path, algo)
    if got != want.lower():
        path.unlink()
        raise FetchError(
            f"{path.name}: {algo} {got} does not match the expected {want}; the file was deleted. "
            "Run again to download it anew; if it fails again the mirror serves another file."
        )
    return sha


# ---------------------------------------------------------------- extraction


def _wanted(member: str, keep: tuple[str, ...]) -> PurePosixPath | None:
    """Path from mav0/ on when the member is a file under mav0/<kept folder>/ (no images)."""
    p = PurePosixPath(member)
    if "__MACOSX" in p.parts or ".." in p.parts or "mav0" not in p.parts:
        return None
    rel = PurePosixPath(*p.parts[p.parts.index("mav0") :])
    if len(rel.parts) != 3 or rel.parts[1] not in keep:  # mav0/<folder>/<file>: no data/ subfolders
        return None
    return rel


def _members(archive: Path) -> Iterator[tuple[str, object]]:
    if zipfile.is_zipfile(archive):
        with zipfile.ZipFile(archive) as zf:
            for info in zf.infolist():
                if not info.is_dir():
                    yield info.filename, lambda info=info, zf=zf: zf.open(info)
    else:
        with tarfile.open(archive, "r:*") as tf:  # streams: a multi-GB tar is read once
            for info in tf:
                if info.isfile():
                    yield info.name, lambda info=info, tf=tf: tf.extractfile(info)


def extract(archive: Path, seq_dir: Path, keep: tuple[str, ...]) -> list[Path]:
    """Write the kept files under seq_dir (atomically each); returns them."""
    written = []
    try:
        for name, opener in _members(archive):
            rel = _wanted(name, keep)
            if rel is None:
                continue
            out = seq_dir.joinpath(*rel.parts)
            with atomic_path(out) as tmp, opener() as src, open(tmp, "wb") as dst:
                shutil.copyfileobj(src, dst, CHUNK)
            written.append(out)
    except (zipfile.BadZipFile, tarfile.TarError, EOFError) as e:
        raise FetchError(f"{archive}: not a readable zip/tar archive ({e}); delete it and run again.") from None
    return written


def is_complete(seq_dir: Path, keep: tuple[str, ...]) -> bool:
    return all((seq_dir / "mav0" / k / "data.csv").is_file() for k in keep)


def fetch_extra_files(ds: Dataset, seq: str, seq_dir: Path, progress: bool = True) -> list[Path]:
    """Download the sequence's extra files that are not there yet; a ground truth is checked by the reader."""
    from gyrodenoise.data.readers import DataFormatError, read_groundtruth

    written = []
    for rel, url in ds.extra_files.get(seq, {}).items():
        path = seq_dir / rel
        if path.is_file():
            continue
        try:  # the sequence itself is there: a failure here is said and the fetch goes on
            download(url, path, progress)
            try:
                read_groundtruth(path)
            except DataFormatError as e:
                path.unlink()
                raise FetchError(f"{url}: not a ground-truth file the loaders read ({e}); deleted it") from None
        except FetchError as e:
            print(
                f"warning: {seq}: {rel} not fetched: {e}. The dataset config reads it; run the same command again to "
                "fetch it, or put the file there by hand",
                file=sys.stderr,
            )
            continue
        written.append(path)
    return written


def extra_file_source(dataset: str, seq: str, rel: str) -> str | None:
    """The URL `fetch` takes `rel` (a path under the sequence folder) from, if it knows one."""
    return DATASETS[dataset].extra_files.get(seq, {}).get(rel) if dataset in DATASETS else None


def fetch(
    dataset: str,
    dest: str | Path,
    sequences: list[str] | None = None,
    base_url: str | None = None,
    keep_archives: bool = False,
    progress: bool = True,
) -> list[Path]:
    """Download and extract the sequences; returns their folders. Complete sequences are skipped."""
    ds = DATASETS[dataset]
    base = (base_url or ds.base_url).rstrip("/")
    names = sequences or list(ds.archives)
    unknown = [s for s in names if s not in ds.archives]
    if unknown:
        raise FetchError(f"unknown {dataset} sequence(s) {unknown}; choose from {list(ds.archives)}")
    dest = Path(dest)
    downloads = dest / ".downloads"
    out = []
    for seq in names:
        seq_dir = dest / seq
        if is_complete(seq_dir, ds.keep):
            print(f"{seq}: already there, skipped", file=sys.stderr)
            fetch_extra_files(ds, seq, seq_dir, progress)
            out.append(seq_dir)
            continue
        archive_rel = ds.archives[seq]
        archive = downloads / PurePosixPath(archive_rel).name
        url = f"{base}/{archive_rel}"
        if not archive.exists():  # else: kept or left by an interrupted run; verified again below
            download(url, archive, progress)
        verify(archive, expected_checksum(ds, base, archive_rel))
        written = extract(archive, seq_dir, ds.keep)
        if not is_complete(seq_dir, ds.keep):
            raise FetchError(
                f"{archive}: no {' and '.join(f'mav0/{k}/data.csv' for k in ds.keep)} inside (found "
                f"{len(written)} kept files). Is this the ASL-format archive of {seq}?"
            )
        if not keep_archives:
            archive.unlink()
        written += fetch_extra_files(ds, seq, seq_dir, progress)
        print(f"{seq}: {', '.join(str(p.relative_to(dest)) for p in written)}", file=sys.stderr)
        out.append(seq_dir)
    if downloads.is_dir() and not any(downloads.iterdir()):
        downloads.rmdir()
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m gyrodenoise.data.fetch",
        description="Download EuRoC / TUM-VI, keeping only IMU and ground truth in the ASL layout.",
        epilog="\n".join(f"{k}: {v.info}" for k, v in DATASETS.items()),
    )
    ap.add_argument("dataset", choices=sorted(DATASETS))
    ap.add_argument("--dest", required=True, type=Path, help="folder that will hold <sequence>/mav0/...")
    ap.add_argument("--sequences", nargs="+", help="subset of sequences (default: all)")
    ap.add_argument("--base-url", help="mirror with the same layout as the official server")
    ap.add_argument("--keep-archives", action="store_true", help="keep the downloaded archives in DEST/.downloads")
    ap.add_argument("--no-progress", action="store_true")
    args = ap.parse_args(argv)
    try:
        fetch(args.dataset, args.dest, args.sequences, args.base_url, args.keep_archives, not args.no_progress)
    except FetchError as e:
        print(f"error: {e}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
