"""The README's first-hour table, timed: a fresh clone of this checkout's HEAD, a fresh virtual environment, an empty
data cache, and each command of the table run as the README gives it, one after the other.

    python benchmarks/first_hour.py --work /tmp/first_hour --data ../shared/data --out benchmarks/results/first_hour

Rows: install (torch pinned, then the package), `train experiment=sim_quick`, `evaluate dataset=euroc`,
`fit_calibrated dataset=euroc`, `train dataset=euroc`, `gyrodenoise-correct` on the first 21,000 lines of MH_01's IMU
file (a user's own recording), the `[rosbag]` extra and `from_bag` on a ROS 1 bag of MH_01's first 60 s (IMU and
ground truth, written before the clock starts with rosbags' own writer, which this script's environment needs: the dev
extra has it), the `[export]` extra and `export euroc --onnx`. Each row: wall time of the command (Python's start
included), exit status, and the command's last line. Writes OUT.md and OUT.json; the work folder (clone, venv,
outputs) is left for inspection. Needs the package registries (pip) and the data folder; CPU only. The machine should
be otherwise idle for figures comparable with the README's.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]


def rows(py: str, work: Path) -> list[tuple[str, list[str]]]:
    """(what, command) in the README's order; `py` is the fresh environment's python."""
    own = work / "my_imu.csv"
    return [
        ("install torch", [py, "-m", "pip", "install", "-q", "torch==2.13.0"]),
        ("install the package", [py, "-m", "pip", "install", "-q", "."]),
        ("train and test on simulated data", [py, "-m", "gyrodenoise.train", "experiment=sim_quick"]),
        ("the shipped EuRoC models on the test flights", [py, "-m", "gyrodenoise.evaluate", "dataset=euroc"]),
        ("the 12-parameter calibrated baseline", [py, "-m", "gyrodenoise.fit_calibrated", "dataset=euroc"]),
        ("train the network on EuRoC", [py, "-m", "gyrodenoise.train", "dataset=euroc"]),
        ("correct your own recording", [str(Path(py).parent / "gyrodenoise-correct"), str(own)]),
        ("the [rosbag] extra", [py, "-m", "pip", "install", "-q", ".[rosbag]"]),
        (
            "a ROS bag to a training sequence",
            [py, "-m", "gyrodenoise.data.from_bag", str(work / "rec.bag"), "--out", str(work / "data" / "rec")],
        ),
        ("the [export] extra", [py, "-m", "pip", "install", "-q", ".[export]"]),
        ("export for onboard use", [py, "-m", "gyrodenoise.export", "euroc", "--onnx", str(work / "euroc.onnx")]),
    ]


def write_bag(seq: Path, bag: Path, seconds: float = 60.0) -> None:
    """The first `seconds` of an ASL sequence as a ROS 1 bag: sensor_msgs/Imu on /imu0, the ground-truth pose as
    geometry_msgs/PoseStamped on /vicon/body (header stamps = the files' stamps), as a recording of one's own."""
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    from gyrodenoise.data.readers import read_groundtruth, read_imu

    ts = get_typestore(Stores.ROS1_NOETIC)
    T = ts.types
    imu = read_imu(seq / "mav0" / "imu0" / "data.csv")
    gt = read_groundtruth(seq / "mav0" / "state_groundtruth_estimate0" / "data.csv")
    end = imu.t_ns[0] + int(seconds * 1e9)

    def header(t: int, frame: str) -> object:
        return T["std_msgs/msg/Header"](
            seq=0, stamp=T["builtin_interfaces/msg/Time"](sec=t // 10**9, nanosec=t % 10**9), frame_id=frame
        )

    def vec(v) -> object:
        return T["geometry_msgs/msg/Vector3"](x=float(v[0]), y=float(v[1]), z=float(v[2]))

    def quat(q) -> object:  # x, y, z, w
        return T["geometry_msgs/msg/Quaternion"](x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3]))

    none = np.zeros(9)
    no_orientation = np.r_[-1.0, np.zeros(8)]  # REP 145: the message has no orientation estimate
    msgs = []
    for t, w, a in zip(imu.t_ns.tolist(), imu.gyro, imu.acc, strict=True):
        if t <= end:
            m = T["sensor_msgs/msg/Imu"](
                header=header(t, "imu4"), orientation=quat([0, 0, 0, 1]), orientation_covariance=no_orientation,
                angular_velocity=vec(w), angular_velocity_covariance=none,
                linear_acceleration=vec(a), linear_acceleration_covariance=none,
            )  # fmt: skip
            msgs.append((t, "imu", ts.serialize_ros1(m, "sensor_msgs/msg/Imu")))
    for t, p, q in zip(gt.t_ns.tolist(), gt.pos, gt.quat_xyzw, strict=True):
        if t <= end:
            point = T["geometry_msgs/msg/Point"](x=float(p[0]), y=float(p[1]), z=float(p[2]))
            pose = T["geometry_msgs/msg/Pose"](position=point, orientation=quat(q))
            m = T["geometry_msgs/msg/PoseStamped"](header=header(t, "world"), pose=pose)
            msgs.append((t, "gt", ts.serialize_ros1(m, "geometry_msgs/msg/PoseStamped")))
    with Writer(bag) as w:
        conns = {
            "imu": w.add_connection("/imu0", "sensor_msgs/msg/Imu", typestore=ts),
            "gt": w.add_connection("/vicon/body", "geometry_msgs/msg/PoseStamped", typestore=ts),
        }
        for t, kind, raw in sorted(msgs, key=lambda m: m[0]):
            w.write(conns[kind], t, raw)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--work", type=Path, required=True, help="an empty folder outside the repository (made)")
    ap.add_argument("--data", type=Path, required=True, help="the folder that holds euroc/ (GYRODENOISE_DATA)")
    ap.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results" / "first_hour")
    args = ap.parse_args()
    work, data = args.work.resolve(), args.data.resolve()
    if work.exists() and any(work.iterdir()):
        ap.error(f"--work {work}: not empty (the clone, venv and cache must be fresh)")
    if not (data / "euroc" / "MH_01_easy").is_dir():
        ap.error(f"--data {data}: no euroc/MH_01_easy in it")
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=REPO, capture_output=True, text=True)
    commit = commit.stdout.strip()
    started = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    work.mkdir(parents=True, exist_ok=True)
    clone = work / "clone"
    subprocess.run(["git", "clone", "-q", str(REPO), str(clone)], check=True)
    subprocess.run([sys.executable, "-m", "venv", str(work / "venv")], check=True)
    lines = (data / "euroc" / "MH_01_easy" / "mav0" / "imu0" / "data.csv").read_text().splitlines(keepends=True)
    (work / "my_imu.csv").write_text("".join(lines[:21001]))  # header + 21,000 samples: 105 s at 200 Hz
    write_bag(data / "euroc" / "MH_01_easy", work / "rec.bag")
    env = {k: v for k, v in os.environ.items() if not k.startswith(("PYTHON", "VIRTUAL_ENV", "OMP_"))}
    # pip's own download cache is kept (as on a machine that installed torch before): installs time the install
    env |= {"GYRODENOISE_DATA": str(data), "GYRODENOISE_CACHE": str(work / "cache")}
    env["PATH"] = f"{work / 'venv' / 'bin'}:{env.get('PATH', '')}"
    results = []
    for what, cmd in rows(str(work / "venv" / "bin" / "python"), work):
        t0 = time.monotonic()
        p = subprocess.run(cmd, cwd=clone, env=env, capture_output=True, text=True)
        wall = time.monotonic() - t0
        last = next((ln for ln in reversed((p.stdout + p.stderr).splitlines()) if ln.strip()), "")
        last = last.replace(str(work), "WORK")
        shown = " ".join(c.replace(str(work), "WORK") for c in cmd)
        results.append({"what": what, "command": shown, "wall_s": round(wall, 1), "rc": p.returncode, "last": last})
        print(f"{what}: {wall:.1f} s, rc {p.returncode}", flush=True)
        (work / f"{len(results):02d}.log").write_text(p.stdout + p.stderr)
    machine = f"{platform.node() or '?'} ({platform.machine()}, {os.cpu_count()} CPU threads)"
    head = [
        "# The first hour, timed (benchmarks/first_hour.py)",
        "",
        f"Command: `python benchmarks/first_hour.py --work WORK --data DATA --out {args.out.name}`  ",
        f"Code: {commit}; machine: {machine}; started {started}.  ",
        "A fresh clone, a fresh virtual environment (pip from the package registries), an empty data cache; each "
        "command as the README's table gives it, one after the other, Python's start included.",
        "",
        "| what | command | wall (s) | exit | last line |",
        "|---|---|---|---|---|",
    ]
    body = [
        f"| {r['what']} | `{r['command'].replace('|', '/')}` | {r['wall_s']} | {r['rc']} | "
        f"{r['last'][:140].replace('|', '/')} |"
        for r in results
    ]
    args.out.parent.mkdir(parents=True, exist_ok=True)
    tmp = args.out.with_suffix(".md.tmp")
    tmp.write_text("\n".join(head + body) + "\n")
    os.replace(tmp, args.out.with_suffix(".md"))
    tmp = args.out.with_suffix(".json.tmp")
    tmp.write_text(json.dumps({"commit": commit, "machine": machine, "rows": results}, indent=2) + "\n")
    os.replace(tmp, args.out.with_suffix(".json"))
    return 0 if all(r["rc"] == 0 for r in results) else 1


if __name__ == "__main__":
    sys.exit(main())
