"""gyrodenoise.data.fetch against a local HTTP server (127.0.0.1) serving small archives of the real layout."""

from __future__ import annotations

import hashlib
import io
import tarfile
import threading
import zipfile
from http.server import SimpleHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

import numpy as np
import pytest

from gyrodenoise.data import fetch as fetch_mod
from gyrodenoise.data.cache import load_sequence
from gyrodenoise.data.fetch import FetchError, download, fetch, main

IMU = "#timestamp [ns],w_x,w_y,w_z,a_x,a_y,a_z\n" + "".join(
    f"{1_403_636_579_000_000_000 + k * 5_000_000},0.01,0.02,-0.01,0.1,0.2,9.8\n" for k in range(400)
)
GT = "#timestamp,p_x,p_y,p_z,q_w,q_x,q_y,q_z\n" + "".join(
    f"{1_403_636_579_000_000_000 + k * 5_000_000},0,0,0,1,0,0,0\n" for k in range(400)
)


def asl_files(gt_dir: str, prefix: str = "") -> dict[str, bytes]:
    m = f"{prefix}mav0/"
    return {
        m + "imu0/data.csv": IMU.encode(),
        m + "imu0/sensor.yaml": b"rate_hz: 200\n",
        m + f"{gt_dir}/data.csv": GT.encode(),
        m + "cam0/data.csv": b"#t,filename\n",
        m + "cam0/data/1403636579000000000.png": b"\x89PNG" + bytes(50_000),  # must not be extracted
        m + "imu0/data/nested.csv": b"not kept",
    }


def make_zip(path: Path, files: dict[str, bytes]) -> None:
    with zipfile.ZipFile(path, "w") as zf:
        for name, data in files.items():
            zf.writestr(name, data)
        zf.writestr("__MACOSX/mav0/imu0/._data.csv", b"junk")


def make_tar(path: Path, files: dict[str, bytes]) -> None:
    with tarfile.open(path, "w") as tf:
        for name, data in files.items():
            info = tarfile.TarInfo(name)
            info.size = len(data)
            tf.addfile(info, io.BytesIO(data))


class RangeHandler(SimpleHTTPRequestHandler):
    """Static files with HTTP Range support; can cut the first response short (a lost connection)."""

    log: list[str] = []
    cut_after: int | None = None  # bytes sent before closing, once
    honour_range = True

    def log_message(self, *args) -> None:  # keep test output quiet
        pass

    def do_GET(self) -> None:
        path = Path(self.translate_path(self.path))
        if not path.is_file():
            self.send_error(404)
            return
        data = path.read_bytes()
        rng = self.headers.get("Range")
        RangeHandler.log.append(f"{self.path} {rng}")
        start = 0
        if rng and self.honour_range:
            start = int(rng.split("=")[1].split("-")[0])
            if start >= len(data):
                self.send_response(416)
                self.send_header("Content-Range", f"bytes */{len(data)}")
                self.end_headers()
                return
            self.send_response(206)
            self.send_header("Content-Range", f"bytes {start}-{len(data) - 1}/{len(data)}")
        else:
            self.send_response(200)
        body = data[start:]
        self.send_header("Content-Length", str(len(body)))
        self.end_headers()
        if RangeHandler.cut_after is not None:
            n, RangeHandler.cut_after = RangeHandler.cut_after, None
            self.wfile.write(body[:n])
            self.close_connection = True
            return
        self.wfile.write(body)


@pytest.fixture()
def server(tmp_path):
    root = tmp_path / "www"
    root.mkdir()
    RangeHandler.log, RangeHandler.cut_after, RangeHandler.honour_range = [], None, True
    handler = lambda *a, **k: RangeHandler(*a, directory=str(root), **k)  # noqa: E731
    httpd = ThreadingHTTPServer(("127.0.0.1", 0), handler)
    thread = threading.Thread(target=httpd.serve_forever, daemon=True)
    thread.start()
    yield root, f"http://127.0.0.1:{httpd.server_address[1]}"
    httpd.shutdown()
    httpd.server_close()


@pytest.fixture(autouse=True)
def _no_sleep(monkeypatch):
    monkeypatch.setattr(fetch_mod.time, "sleep", lambda s: None)


def euroc_archive(root: Path, seq: str = "MH_01_easy") -> Path:
    p = root / "machine_hall" / seq / f"{seq}.zip"
    p.parent.mkdir(parents=True)
    make_zip(p, asl_files("state_groundtruth_estimate0"))
    return p


def test_euroc_zip_keeps_only_imu_and_gt(server, tmp_path):
    root, url = server
    euroc_archive(root)
    dest = tmp_path / "euroc"
    assert main(["euroc", "--dest", str(dest), "--base-url", url, "--sequences", "MH_01_easy", "--no-progress"]) == 0
    files = sorted(str(p.relative_to(dest)) for p in dest.rglob("*") if p.is_file())
    assert files == [
        "MH_01_easy/mav0/imu0/data.csv",
        "MH_01_easy/mav0/imu0/sensor.yaml",
        "MH_01_easy/mav0/state_groundtruth_estimate0/data.csv",
    ]
    assert not (dest / ".downloads").exists()  # archive removed after extraction
    seq = load_sequence(dest, "MH_01_easy", cache_dir="")  # the loaders read it
    assert len(seq) == 400 and np.allclose(seq.gyro[0], [0.01, 0.02, -0.01])
    # a second run skips the complete sequence without any request
    n = len(RangeHandler.log)
    fetch("euroc", dest, ["MH_01_easy"], url, progress=False)
    assert len(RangeHandler.log) == n


def test_resume_after_lost_connection(server, tmp_path):
    root, url = server
    archive = euroc_archive(root)
    data = archive.read_bytes()
    RangeHandler.cut_after = len(data) // 3
    out = download(f"{url}/machine_hall/MH_01_easy/MH_01_easy.zip", tmp_path / "a.zip", progress=True)
    assert out.read_bytes() == data
    assert RangeHandler.log[0].endswith("None") and RangeHandler.log[1].endswith(f"bytes={len(data) // 3}-")


def test_resume_from_partial_file_of_an_earlier_run(server, tmp_path):
    root, url = server
    data = euroc_archive(root).read_bytes()
    (tmp_path / "a.zip.part").write_bytes(data[:1000])
    download(f"{url}/machine_hall/MH_01_easy/MH_01_easy.zip", tmp_path / "a.zip", progress=False)
    assert (tmp_path / "a.zip").read_bytes() == data and RangeHandler.log == [
        "/machine_hall/MH_01_easy/MH_01_easy.zip bytes=1000-"
    ]
    # a whole .part left behind (416 from the server) is accepted as is
    (tmp_path / "b.zip.part").write_bytes(data)
    download(f"{url}/machine_hall/MH_01_easy/MH_01_easy.zip", tmp_path / "b.zip", progress=False)
    assert (tmp_path / "b.zip").read_bytes() == data


def test_server_without_range_support_restarts(server, tmp_path):
    root, url = server
    data = euroc_archive(root).read_bytes()
    RangeHandler.honour_range = False
    (tmp_path / "a.zip.part").write_bytes(b"x" * 500)
    download(f"{url}/machine_hall/MH_01_easy/MH_01_easy.zip", tmp_path / "a.zip", progress=False)
    assert (tmp_path / "a.zip").read_bytes() == data


def test_checksum_mismatch_and_pinned(server, tmp_path, monkeypatch):
    root, url = server
    data = euroc_archive(root).read_bytes()
    monkeypatch.setitem(fetch_mod.CHECKSUMS, "MH_01_easy.zip", "sha256:" + "0" * 64)
    with pytest.raises(FetchError, match="does not match"):
        fetch("euroc", tmp_path / "d", ["MH_01_easy"], url, progress=False)
    assert not list((tmp_path / "d").rglob("*.zip*"))  # the bad file is gone
    monkeypatch.setitem(fetch_mod.CHECKSUMS, "MH_01_easy.zip", "sha256:" + hashlib.sha256(data).hexdigest())
    assert fetch("euroc", tmp_path / "d", ["MH_01_easy"], url, progress=False)


def test_tumvi_tar_with_server_md5(server, tmp_path):
    root, url = server
    name = "dataset-room1_512_16"
    make_tar(root / f"{name}.tar", asl_files("mocap0", prefix=f"{name}/"))
    md5 = hashlib.md5((root / f"{name}.tar").read_bytes()).hexdigest()
    (root / f"{name}.md5").write_text(f"{md5}  {name}.tar\n")
    dest = tmp_path / "tumvi"
    fetch("tumvi", dest, [name], url, keep_archives=True, progress=False)
    assert (dest / name / "mav0" / "mocap0" / "data.csv").read_text() == GT
    assert not (dest / name / "mav0" / "cam0").exists()
    assert (dest / ".downloads" / f"{name}.tar").is_file()
    (root / f"{name}.md5").write_text(f"{'f' * 32}  {name}.tar\n")  # a corrupted mirror is caught
    with pytest.raises(FetchError, match="md5"):
        fetch("tumvi", tmp_path / "t2", [name], url, progress=False)


def test_missing_file_and_unknown_sequence(server, tmp_path, capsys):
    _, url = server
    assert main(["euroc", "--dest", str(tmp_path), "--base-url", url, "--sequences", "V1_01_easy"]) == 1
    assert "HTTP 404" in capsys.readouterr().err
    with pytest.raises(FetchError, match="unknown euroc sequence"):
        fetch("euroc", tmp_path, ["MH_99"], url)


def test_archive_without_imu(server, tmp_path):
    root, url = server
    p = root / "machine_hall" / "MH_02_easy" / "MH_02_easy.zip"
    p.parent.mkdir(parents=True)
    make_zip(p, {"readme.txt": b"hello"})
    with pytest.raises(FetchError, match="ASL-format archive"):
        fetch("euroc", tmp_path / "d", ["MH_02_easy"], url, progress=False)


def test_euroc_v1_01_gets_the_recomputed_ground_truth_its_config_names(server, tmp_path, monkeypatch, capsys):
    """The EuRoC config scores V1_01_easy against OpenVINS's recomputed truth: fetch downloads it beside the archive's
    (also into a sequence fetched before), and a missing one says where it comes from and how to go without it."""
    root, url = server
    seq, rel = "V1_01_easy", "mav0/state_groundtruth_estimate0/data_recomputed_openvins.csv"
    p = root / "vicon_room1" / seq / f"{seq}.zip"
    p.parent.mkdir(parents=True)
    make_zip(p, asl_files("state_groundtruth_estimate0"))
    (root / "recomputed.csv").write_text(GT)
    ds = fetch_mod.DATASETS["euroc"]
    monkeypatch.setitem(ds.extra_files, seq, {rel: f"{url}/recomputed.csv"})
    dest = tmp_path / "euroc"
    fetch("euroc", dest, [seq], url, progress=False)
    assert (dest / seq / rel).read_text() == GT
    load_sequence(dest, seq, rel.removeprefix("mav0/"), cache_dir="")

    (dest / seq / rel).unlink()  # a sequence fetched before: the missing file is named with the command
    with pytest.raises(FileNotFoundError) as e:
        load_sequence(dest, seq, rel.removeprefix("mav0/"), cache_dir="")
    msg = str(e.value)
    assert f"python -m gyrodenoise.data.fetch euroc --dest {dest} --sequences {seq}" in msg and "recomputed.csv" in msg
    assert f"'~dataset.gt_files.{seq}'" in msg
    fetch("euroc", dest, [seq], url, progress=False)  # complete sequence: only the extra file is downloaded
    assert (dest / seq / rel).is_file() and RangeHandler.log[-1].startswith("/recomputed.csv")

    (root / "recomputed.csv").write_text("<html>moved</html>\n")  # a mirror's error page is not kept; said, and
    (dest / seq / rel).unlink()  # the fetch goes on (the sequence itself is there)
    assert fetch("euroc", dest, [seq], url, progress=False) == [dest / seq]
    assert not (dest / seq / rel).exists()
    assert "not a ground-truth file the loaders read" in capsys.readouterr().err
