"""A ROS bag (ROS 1 .bag, a ROS 2 bag folder, or a bare .mcap file) to one sequence in the ASL layout.

    python -m gyrodenoise.data.from_bag BAG --list
    python -m gyrodenoise.data.from_bag BAG --out ROOT/NAME [--imu-topic T] [--gt-topic T | --no-gt]

The IMU topic (sensor_msgs/Imu, SI units by ROS convention REP 145) becomes mav0/imu0/data.csv; a pose topic
(geometry_msgs/PoseStamped, PoseWithCovarianceStamped, TransformStamped, nav_msgs/Odometry, or one parent-child
pair of a tf2_msgs/TFMessage topic such as /tf: a motion-capture or ground-truth pose of the body in a world frame)
becomes mav0/state_groundtruth_estimate0/data.csv, so that `dataset=asl_folder dataset.root=ROOT` trains on it and
`gyrodenoise-correct ROOT/NAME` corrects it. Stamps are the messages' header stamps (the sensors' clocks) unless
`--stamp record` takes the time the bag recorded them. The written files are read back by the project's readers,
and the IMU checked against the pose (units, axes, clock) before the command says it is done. Reading bags needs
the `rosbags` package: pip install "gyrodenoise[rosbag]".
"""

from __future__ import annotations

import argparse
import json
import math
import shutil
import sys
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from gyrodenoise.data.asl_write import GT_FILE, IMU_FILE, pose_values, write_sequence
from gyrodenoise.data.consistency import AXES_MAX_DEG, GyroUnitError, noting_data_warnings
from gyrodenoise.data.readers import QUAT_NORM_TOL, DataFormatError, quaternion_norms
from gyrodenoise.paths import portable_path

IMU_TYPE = "sensor_msgs/msg/Imu"
TF_TYPE = "tf2_msgs/msg/TFMessage"
IMPORT_RECORD = "bag_import.json"  # beside mav0: marks a folder this command wrote (--overwrite replaces only those)


def _pose(m: object) -> object:  # geometry_msgs/Pose: position, orientation
    return m.pose


def _pose_of_cov(m: object) -> object:
    return m.pose.pose


class _TransformAsPose:
    def __init__(self, m: object) -> None:
        self.position, self.orientation = m.transform.translation, m.transform.rotation


# the pose messages read as ground truth, and where their geometry_msgs/Pose is
POSE_TYPES: dict[str, Callable[[object], object]] = {
    "geometry_msgs/msg/PoseStamped": _pose,
    "geometry_msgs/msg/PoseWithCovarianceStamped": _pose_of_cov,
    "nav_msgs/msg/Odometry": _pose_of_cov,
    "geometry_msgs/msg/TransformStamped": _TransformAsPose,
}
NOT_A_POSE = {  # a type users reach for that carries no orientation
    "geometry_msgs/msg/PointStamped": "a position only (no orientation): it cannot train a gyro",
}
GYRO_UNITS = {"rad/s": 1.0, "deg/s": math.pi / 180.0}
REPAIR = "repair it (MCAP: `mcap recover`; ROS 1: `rosbag reindex`) and import the repaired file"


class BagError(DataFormatError):
    """A bag, topic or message that cannot become a sequence; the message says which and what to do."""


@dataclass
class Stream:
    """One topic's messages as arrays, in time order."""

    topic: str
    t_ns: np.ndarray
    values: np.ndarray
    notes: list[str] = field(default_factory=list)


def _open(bag: Path):  # noqa: ANN202 - rosbags' AnyReader; imported here so that the package does not need it
    try:
        from rosbags.highlevel import AnyReader
        from rosbags.typesys import Stores, get_typestore
    except ImportError:
        raise BagError(
            'reading ROS bags needs the rosbags package: pip install "gyrodenoise[rosbag]" (or pip install rosbags)'
        ) from None
    if not bag.exists():
        raise FileNotFoundError(f"{bag}: no such bag (a ROS 1 .bag file, a ROS 2 bag folder, or a .mcap file)")
    if bag.is_dir() and not (bag / "metadata.yaml").is_file():
        files = sorted(p.name for p in bag.iterdir() if p.suffix in (".mcap", ".db3"))
        mcap = [f for f in files if f.endswith(".mcap")]
        what = (
            f"; a .mcap file is read on its own: give {bag / mcap[0]}" if mcap else f" (it holds {files or 'no bag'})"
        )
        raise BagError(f"{bag}: a ROS 2 bag folder needs its metadata.yaml, and this one has none{what}")
    # ROS 2 bags written without their message definitions are read with the standard types of a recent release
    return AnyReader([bag], default_typestore=get_typestore(Stores.LATEST))


def _damaged(bag: Path, what: str, e: Exception) -> BagError:
    return BagError(f"{bag}: {what} failed ({type(e).__name__}: {e}): the bag is damaged or cut short; {REPAIR}")


def topics(bag: Path) -> list[tuple[str, str, int]]:
    """(topic, message type, message count) of every topic in the bag."""
    try:
        with _open(bag) as reader:
            return sorted((c.topic, c.msgtype, c.msgcount) for c in reader.connections)
    except (BagError, FileNotFoundError):
        raise
    except Exception as e:  # rosbags' own errors (not a bag, damaged index): one line with the file
        why = f"{type(e).__name__}: {e}"
        raise BagError(f"{bag}: cannot be read as a ROS bag ({why}); if it is one, {REPAIR}") from None


def _messages(bag: Path, topic: str) -> Iterator[tuple[int, object]]:
    """(record time ns, message) of a topic, in the bag's order; a damaged bag is one line, not a trace."""
    try:
        with _open(bag) as reader:
            conns = [c for c in reader.connections if c.topic == topic]
            for conn, t_record, raw in reader.messages(connections=conns):
                yield int(t_record), reader.deserialize(raw, conn.msgtype)
    except (BagError, FileNotFoundError):
        raise
    except Exception as e:
        raise _damaged(bag, f"reading {topic}", e) from None


def _frame(name: str) -> str:
    return name.lstrip("/")


def tf_pairs(bag: Path, topic: str) -> dict[tuple[str, str], int]:
    """{(parent, child): transforms} of a tf2_msgs/TFMessage topic, to choose --tf-frames from."""
    pairs: dict[tuple[str, str], int] = {}
    for _, m in _messages(bag, topic):
        for tf in m.transforms:
            key = (_frame(tf.header.frame_id), _frame(tf.child_frame_id))
            pairs[key] = pairs.get(key, 0) + 1
    return pairs


def _listing(found: list[tuple[str, str, int]]) -> str:
    return "; ".join(f"{t} ({ty}, {n} messages)" for t, ty, n in found) or "no topics"


def choose_topics(
    bag: Path, found: list[tuple[str, str, int]], imu_topic: str | None, gt_topic: str | None, no_gt: bool
) -> tuple[str, str | None]:
    """The IMU topic and the pose topic (None: IMU only): the ones named, else the only one of its kind."""
    by_topic = {t: ty for t, ty, _ in found}
    imus = [t for t, ty, _ in found if ty == IMU_TYPE]
    poses = [t for t, ty, _ in found if ty in POSE_TYPES]
    if imu_topic is None:
        if not imus:
            raise BagError(f"{bag}: no sensor_msgs/Imu topic: nothing to import. The bag holds: {_listing(found)}")
        if len(imus) > 1:
            raise BagError(f"{bag}: {len(imus)} sensor_msgs/Imu topics: {', '.join(imus)}; name one with --imu-topic")
        imu_topic = imus[0]
    elif by_topic.get(imu_topic) != IMU_TYPE:
        what = f"is a {by_topic[imu_topic]}" if imu_topic in by_topic else "is not in the bag"
        raise BagError(f"{bag}: --imu-topic {imu_topic} {what}; sensor_msgs/Imu topics: {', '.join(imus) or 'none'}")
    if no_gt:
        return imu_topic, None
    if gt_topic is None:
        if len(poses) > 1:
            raise BagError(
                f"{bag}: several pose topics ({', '.join(poses)}); name the ground truth with --gt-topic, or "
                "write the IMU alone with --no-gt"
            )
        return imu_topic, (poses[0] if poses else None)
    ty = by_topic.get(gt_topic)
    if ty not in POSE_TYPES and ty != TF_TYPE:
        why = NOT_A_POSE.get(ty, f"a {ty}" if ty else "not in the bag")
        raise BagError(
            f"{bag}: --gt-topic {gt_topic} is {why}. Ground truth is read from {', '.join(sorted(POSE_TYPES))} or a "
            f"{TF_TYPE} topic with --tf-frames; pose topics in this bag: {', '.join(poses) or 'none'}"
        )
    return imu_topic, gt_topic


def _imu_row(m: object) -> list[float]:
    w, a = m.angular_velocity, m.linear_acceleration
    return [w.x, w.y, w.z, a.x, a.y, a.z]


def _pose_row(p: object) -> list[float]:
    q = p.orientation
    return [p.position.x, p.position.y, p.position.z, q.x, q.y, q.z, q.w]


def _stamp_ns(header: object) -> int:
    return int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)


def _rows(
    bag: Path, topic: str, msgtype: str, tf_frames: tuple[str, str] | None
) -> tuple[list[int], list[int], list[list[float]]]:
    """Header stamps, record times and value rows of a topic (for a TF topic: of its `tf_frames` pair)."""
    t, rec, values = [], [], []
    if msgtype == TF_TYPE:
        if tf_frames is None:
            raise BagError(f"{bag}: {topic} holds transforms of several frames: choose a pair, {_tf_hint(bag, topic)}")
        want = tuple(_frame(f) for f in tf_frames)
        for t_record, m in _messages(bag, topic):
            for tf in m.transforms:
                if (_frame(tf.header.frame_id), _frame(tf.child_frame_id)) == want:
                    t.append(_stamp_ns(tf.header))
                    rec.append(t_record)
                    values.append(_pose_row(_TransformAsPose(tf)))
        if not values:
            raise BagError(f"{bag}: {topic} has no transform {want[0]} -> {want[1]}; {_tf_hint(bag, topic)}")
        return t, rec, values
    row = _imu_row if msgtype == IMU_TYPE else (lambda m, pose_of=POSE_TYPES[msgtype]: _pose_row(pose_of(m)))
    for t_record, m in _messages(bag, topic):
        t.append(_stamp_ns(m.header))
        rec.append(t_record)
        values.append(row(m))
    return t, rec, values


def _tf_hint(bag: Path, topic: str) -> str:
    pairs = sorted(tf_pairs(bag, topic).items(), key=lambda kv: -kv[1])
    listed = ", ".join(f"{p} {c} ({n})" for (p, c), n in pairs[:10]) + (" ..." if len(pairs) > 10 else "")
    return f"--tf-frames PARENT CHILD (pairs there, with their transforms: {listed or 'none'})"


def read_stream(bag: Path, topic: str, msgtype: str, stamp: str, tf_frames: tuple[str, str] | None = None) -> Stream:
    """A topic's stamps (int ns: header stamps, or the bag's record times) and values, sorted by stamp. Messages
    recorded twice (same stamp, same values) are dropped with a note; other repeated stamps are refused."""
    t, rec, values = _rows(bag, topic, msgtype, tf_frames)
    if not values:
        raise BagError(f"{bag}: topic {topic} has no messages")
    t_ns = np.asarray(rec if stamp == "record" else t, dtype=np.int64)
    v = np.asarray(values, dtype=np.float64)
    if stamp == "header" and (t_ns <= 0).any():
        raise BagError(
            f"{bag}: {topic}: {(t_ns <= 0).sum()} of {len(t_ns)} messages have no header stamp (0): the driver did "
            "not set it. Use --stamp record: every topic read (the pose too) then takes the time the bag recorded "
            "it, which carries the transport's delay and jitter"
        )
    bad = ~np.isfinite(v).all(1)
    if bad.any():
        k = int(np.argmax(bad))
        raise BagError(
            f"{bag}: {topic}: {bad.sum()} messages with NaN/inf values, the first the {k + 1}th (t {t_ns[k]} ns): "
            "gyrodenoise does not fill them in silently; remove them from the bag"
        )
    order = np.lexsort((np.arange(len(t_ns)), t_ns))  # by stamp, stable
    s = Stream(topic, t_ns[order], v[order])
    if reordered := int((order != np.arange(len(order))).sum()):
        s.notes.append(f"{topic}: {reordered} messages were out of time order in the bag and are written sorted")
    same_t = np.diff(s.t_ns) == 0
    copies = same_t & (s.values[1:] == s.values[:-1]).all(1)
    if copies.any():  # a message recorded twice (a relay, a merged bag): the same sample, kept once
        keep = np.r_[True, ~copies]
        s.t_ns, s.values = s.t_ns[keep], s.values[keep]
        s.notes.append(f"{topic}: {int(copies.sum())} messages recorded twice (same stamp, same values) kept once")
        same_t = np.diff(s.t_ns) == 0
    if same_t.any():
        k = int(np.argmax(same_t))
        hint = (
            "the header clock is coarser than the stream; try --stamp record"
            if stamp == "header"
            else "the bag recorded them in the same nanosecond; try --stamp header"
        )
        raise BagError(
            f"{bag}: {topic}: {same_t.sum()} messages with other values repeat the stamp of the one before (the "
            f"first at {s.t_ns[k]} ns): {hint}"
        )
    return s


def body_to_imu(gt: Stream, imu_in_body: Rotation) -> np.ndarray:
    """Ground-truth columns of the IMU's own orientation: R_world_imu = R_world_body R_body_imu."""
    q = gt.values[:, 3:]
    norm, k, count = quaternion_norms(q)
    if k is not None:
        raise BagError(
            f"{gt.topic}: {count} orientations are not unit quaternions (|q| = {norm[k]:.3g} at {gt.t_ns[k]} ns; "
            "a zero quaternion means no pose): remove those messages or record the ground truth without them"
        )
    rot = Rotation.from_quat(q / norm[:, None]) * imu_in_body
    return pose_values(gt.values[:, :3], rot.as_quat())


def check_written(folder: Path, imu_topic: str, with_gt: bool, imu_in_body: Rotation) -> tuple[list[str], list[str]]:
    """Read the written sequence back with the project's readers; with ground truth, check the IMU against it.
    Returns the data warnings and the advice for this importer's options."""
    from gyrodenoise.data.consistency import check
    from gyrodenoise.data.readers import read_groundtruth, read_imu
    from gyrodenoise.data.sequence import build_sequence

    imu = read_imu(folder / IMU_FILE)
    if not with_gt:
        return [], []
    try:
        with noting_data_warnings() as found:
            m = check(build_sequence(folder.name, imu, read_groundtruth(folder / GT_FILE)))
    except GyroUnitError as e:
        raise BagError(
            f"{imu_topic}: the gyro is {e.ratio:.1f} times the rate of the pose's orientation: it is in deg/s (ROS "
            "messages are in rad/s, REP 145, but some drivers differ). Rerun with --gyro-unit deg/s"
        ) from None
    advice = []
    if m.axes_fit is not None and not m.mirrored and m.axes_angle_deg > AXES_MAX_DEG:
        fix = imu_in_body * m.axes_fit.inv()  # the IMU frame in the pose's body frame, as the gyro sees it
        advice.append(
            f"the gyro turns about axes {m.axes_angle_deg:.0f} deg away from the pose's body axes: if the pose is of "
            "a body the IMU is rotated in (a mocap marker set), rerun the same command with --imu-in-body "
            + " ".join(f"{x:.6f}" for x in fix.as_quat(canonical=True))
            + " --overwrite (x y z w, fitted from the rates)"
        )
    return found, advice


def check_out(bag: Path, out: Path, overwrite: bool) -> None:
    """--out must be a new or empty folder, or one this command wrote before (with --overwrite): a sequence folder
    is replaced whole, so anything else there (other sequences, the bag itself) would be lost."""
    b, o = bag.resolve(), out.resolve()
    if b == o or o in b.parents:
        raise BagError(f"--out {out} holds the bag itself: write the sequence to another folder")
    if out.is_file():
        raise BagError(f"--out {out} is a file: give the sequence folder to write (ROOT/NAME)")
    if not out.is_dir() or not any(out.iterdir()):
        return
    if not (out / IMPORT_RECORD).is_file():
        raise BagError(
            f"--out {out} exists and is not a sequence this command wrote (no {IMPORT_RECORD}): give ROOT/NAME, a "
            "new folder for this recording (--overwrite replaces only an earlier import)"
        )
    if not overwrite:
        raise FileExistsError(f"{out} holds an earlier import; choose another --out or pass --overwrite")


def import_bag(
    bag: str | Path,
    out: str | Path,
    imu_topic: str | None = None,
    gt_topic: str | None = None,
    no_gt: bool = False,
    stamp: str = "header",
    imu_in_body_xyzw: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0),
    gt_time_offset_s: float = 0.0,
    overwrite: bool = False,
    tf_frames: tuple[str, str] | None = None,
    gyro_unit: str = "rad/s",
) -> dict:
    """Write the bag's IMU (and pose) topic as the ASL sequence `out`; returns what was done (also written to
    `out`/bag_import.json). Raises BagError (a DataFormatError) with the bag, topic and what to do."""
    bag, out = Path(bag), Path(out)
    if stamp not in ("header", "record"):
        raise BagError(f"--stamp {stamp}: use header (the sensors' clocks) or record (the bag's clock)")
    if gyro_unit not in GYRO_UNITS:
        raise BagError(f"--gyro-unit {gyro_unit}: use one of {', '.join(GYRO_UNITS)}")
    check_out(bag, out, overwrite)
    found = topics(bag)
    imu_topic, gt_topic = choose_topics(bag, found, imu_topic, gt_topic, no_gt)
    types = {t: ty for t, ty, _ in found}
    imu = read_stream(bag, imu_topic, IMU_TYPE, stamp)
    imu.values[:, :3] *= GYRO_UNITS[gyro_unit]
    gt = read_stream(bag, gt_topic, types[gt_topic], stamp, tf_frames) if gt_topic else None
    imu_in_body = Rotation.from_quat(imu_in_body_xyzw)
    summary = {
        "bag": portable_path(bag),
        "imu_topic": imu_topic,
        "gyro_unit_in_bag": gyro_unit,
        "gt_topic": gt_topic,
        "gt_type": types.get(gt_topic),
        "tf_frames": list(tf_frames) if gt_topic and types[gt_topic] == TF_TYPE else None,
        "stamp": stamp,
        "imu_messages": len(imu.t_ns),
        "imu_rate_hz": float(1e9 / np.median(np.diff(imu.t_ns))) if len(imu.t_ns) > 1 else None,
        "gt_messages": len(gt.t_ns) if gt else 0,
        "imu_in_body_xyzw": list(imu_in_body.as_quat()),
        "gt_time_offset_s": gt_time_offset_s,
        "notes": imu.notes + (gt.notes if gt else []),
    }
    if gt is None:
        tf = [t for t, ty, _ in found if ty == TF_TYPE]
        use_tf = (
            f"; {', '.join(tf)} holds transforms: --gt-topic {tf[0]} --tf-frames PARENT CHILD (see --list)"
            if tf
            else ""
        )
        summary["notes"].append(
            "no ground-truth pose topic: IMU only (gyrodenoise-correct reads it; training needs a pose)" + use_tf
        )
    gt_t = gt.t_ns + int(round(gt_time_offset_s * 1e9)) if gt else None
    folder = write_sequence(
        out,
        imu.t_ns,
        imu.values,
        gt_t,
        body_to_imu(gt, imu_in_body) if gt else None,
        extra_files={IMPORT_RECORD: json.dumps(summary, indent=2) + "\n"},
    )
    try:
        warnings_found, advice = check_written(folder, imu_topic, gt is not None, imu_in_body)
    except DataFormatError as e:  # e.g. a gyro in deg/s: leave no sequence that looks usable
        shutil.rmtree(folder, ignore_errors=True)
        raise BagError(f"{e} ({folder} was not kept)") from None
    summary.update(output=str(folder), data_warnings=warnings_found, advice=advice)
    return summary


def _quat(text: list[str]) -> tuple[float, float, float, float]:
    q = np.asarray([float(x) for x in text])
    n = np.linalg.norm(q)
    if abs(n - 1.0) > QUAT_NORM_TOL:
        raise BagError(f"--imu-in-body {' '.join(text)}: |q| = {n:.4g}, not a unit quaternion (x y z w)")
    return tuple(q / n)


def _print_list(bag: Path) -> None:
    for t, ty, n in topics(bag):
        kind = "IMU" if ty == IMU_TYPE else "pose" if ty in POSE_TYPES else "transforms" if ty == TF_TYPE else ""
        print(f"{t}\t{ty}\t{n}\t{kind}")
        if ty == TF_TYPE:
            for (parent, child), k in sorted(tf_pairs(bag, t).items()):
                print(f"\t--tf-frames {parent} {child}\t{k}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m gyrodenoise.data.from_bag",
        description="Write a ROS bag's IMU topic (and a ground-truth pose topic) as one sequence in the ASL layout "
        "that dataset=asl_folder trains on and gyrodenoise-correct corrects.",
        epilog='Needs pip install "gyrodenoise[rosbag]". Then: python -m gyrodenoise.train dataset=asl_folder '
        "dataset.root=ROOT 'dataset.train_seqs=[NAME,...]' ...",
    )
    ap.add_argument("bag", type=Path, help="a ROS 1 .bag file, a ROS 2 bag folder (metadata.yaml), or a .mcap file")
    ap.add_argument("--list", action="store_true", help="list the topics (type, messages; /tf: its frame pairs)")
    ap.add_argument("--out", type=Path, help="the sequence folder to write: ROOT/NAME (new, or an earlier import)")
    ap.add_argument("--imu-topic", help="sensor_msgs/Imu topic (default: the only one)")
    ap.add_argument("--gt-topic", help="pose topic of the ground truth (default: the only one, if any)")
    ap.add_argument(
        "--tf-frames", nargs=2, metavar=("PARENT", "CHILD"), help="with a tf2_msgs/TFMessage --gt-topic (/tf): the pair"
    )
    ap.add_argument("--no-gt", action="store_true", help="write the IMU alone, even if the bag has a pose topic")
    ap.add_argument(
        "--stamp",
        choices=("header", "record"),
        default="header",
        help="header: the messages' header stamps (default); record: the time the bag recorded each message",
    )
    ap.add_argument(
        "--gyro-unit", choices=list(GYRO_UNITS), default="rad/s", help="the bag's gyro unit (ROS: rad/s, REP 145)"
    )
    ap.add_argument(
        "--imu-in-body",
        nargs=4,
        metavar=("QX", "QY", "QZ", "QW"),
        default=["0", "0", "0", "1"],
        help="the IMU frame's orientation in the pose's body frame (e.g. a mocap marker set), as a quaternion "
        "x y z w; the ground truth written is the IMU's orientation (default: the same frame)",
    )
    ap.add_argument("--gt-time-offset", type=float, default=0.0, help="seconds added to the ground truth's stamps")
    ap.add_argument("--overwrite", action="store_true", help="replace an earlier import at --out")
    args = ap.parse_args(argv)
    try:
        if args.list:
            _print_list(args.bag)
            return 0
        if args.out is None:
            ap.error("--out ROOT/NAME is required (or --list)")
        s = import_bag(
            args.bag,
            args.out,
            args.imu_topic,
            args.gt_topic,
            args.no_gt,
            args.stamp,
            _quat(args.imu_in_body),
            args.gt_time_offset,
            args.overwrite,
            tuple(args.tf_frames) if args.tf_frames else None,
            args.gyro_unit,
        )
    except (DataFormatError, FileNotFoundError, FileExistsError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    rate = f", {s['imu_rate_hz']:.1f} Hz" if s["imu_rate_hz"] else ""
    gt = f"; {s['gt_messages']} poses from {s['gt_topic']}" if s["gt_topic"] else ""
    print(
        f"wrote {s['output']}: {s['imu_messages']} IMU samples from {s['imu_topic']}{rate}{gt} (stamps: {s['stamp']})"
    )
    for line in s["notes"] + s["advice"]:
        print(f"note: {line}")
    for line in s["data_warnings"]:
        print(f"warning: {line}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
