"""A ROS bag (ROS 1 .bag, a ROS 2 bag folder, or a bare .mcap file) to one sequence in the ASL layout.

    python -m gyrodenoise.data.from_bag BAG --list
    python -m gyrodenoise.data.from_bag BAG --out ROOT/NAME [--imu-topic T] [--gt-topic T | --no-gt]

The IMU topic (sensor_msgs/Imu, SI units by ROS convention REP 145) becomes mav0/imu0/data.csv; a pose topic
(geometry_msgs/PoseStamped, PoseWithCovarianceStamped, TransformStamped, nav_msgs/Odometry, or the pose of one frame
in another from a tf2_msgs/TFMessage topic such as /tf, `--tf-frames PARENT CHILD`, composed along the chain of /tf
and /tf_static links that joins them: a motion-capture or ground-truth pose of the body in a world frame) becomes
mav0/state_groundtruth_estimate0/data.csv, so that `dataset=asl_folder dataset.root=ROOT` trains on it and
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

from gyrodenoise import atomic
from gyrodenoise.data.asl_write import GT_FILE, IMU_FILE, pose_values, write_sequence
from gyrodenoise.data.consistency import AXES_MAX_DEG, GyroUnitError, noting_data_warnings
from gyrodenoise.data.readers import QUAT_NORM_TOL, DataFormatError, quaternion_norms
from gyrodenoise.data.tf_chain import MAX_GAP_FACTOR, Step, compose, coverage, find_path, path_frames, resample
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


def _rows(bag: Path, topic: str, msgtype: str) -> tuple[list[int], list[int], list[list[float]]]:
    """Header stamps, record times and value rows of an IMU or pose topic."""
    t, rec, values = [], [], []
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


def read_stream(bag: Path, topic: str, msgtype: str, stamp: str) -> Stream:
    """An IMU or pose topic's stamps (int ns: header stamps, or the bag's record times) and values, sorted by stamp
    (see as_stream). A tf2_msgs/TFMessage topic is read by read_tf_chain."""
    if msgtype == TF_TYPE:
        raise BagError(f"{bag}: {topic} holds transforms of several frames: choose a pair, {_tf_hint(bag, topic)}")
    return as_stream(bag, topic, *_rows(bag, topic, msgtype), stamp)


def as_stream(bag: Path, topic: str, t: list[int], rec: list[int], values: list[list[float]], stamp: str) -> Stream:
    """Rows of one topic (or one tf link, named by `topic`) as a Stream sorted by stamp. Messages recorded twice
    (same stamp, same values) are dropped with a note; other repeated stamps are refused."""
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


def is_static_tf(topic: str) -> bool:
    """A latched topic of constant transforms: /tf_static (or a namespaced .../tf_static)."""
    return topic.rstrip("/").rsplit("/", 1)[-1] == "tf_static"


Rows = tuple[list[int], list[int], list[list[float]]]  # header stamps, record times, values (x y z qx qy qz qw)


def _tf_rows(bag: Path, topic: str) -> dict[tuple[str, str], Rows]:
    """{(parent, child): rows} of every transform on a tf2_msgs/TFMessage topic."""
    rows: dict[tuple[str, str], Rows] = {}
    for t_record, m in _messages(bag, topic):
        for tf in m.transforms:
            t, rec, values = rows.setdefault((_frame(tf.header.frame_id), _frame(tf.child_frame_id)), ([], [], []))
            t.append(_stamp_ns(tf.header))
            rec.append(t_record)
            values.append(_pose_row(_TransformAsPose(tf)))
    return rows


@dataclass
class TfLinks:
    """The links of a bag's frame tree: moving ones (the ground-truth topic's rows) and constant ones (tf_static's
    last value), with the topic and transform count of each."""

    moving: dict[tuple[str, str], Rows]
    static: dict[tuple[str, str], np.ndarray]
    source: dict[tuple[str, str], tuple[str, int]]
    notes: list[str] = field(default_factory=list)


def read_tf_links(bag: Path, topic: str, static_topics: list[str]) -> TfLinks:
    """The links on `topic` (moving; none if it is itself a tf_static topic) and on `static_topics` (constant)."""
    moving = {} if is_static_tf(topic) else _tf_rows(bag, topic)
    links = TfLinks(moving, {}, {pair: (topic, len(r[2])) for pair, r in moving.items()})
    for st in static_topics:
        for pair, (_, _, values) in _tf_rows(bag, st).items():
            name = f"{pair[0]} -> {pair[1]}"
            if pair in moving:
                links.notes.append(f"{name} is on both {topic} and {st}: the moving transforms of {topic} are used")
                continue
            v = np.asarray(values, dtype=np.float64)
            if not np.isfinite(v).all():
                raise BagError(f"{bag}: {st}: {name} holds NaN/inf values; remove that transform from the bag")
            if pair in links.static:  # the same pair on two static topics: one more value, the later topic's wins
                v = np.vstack([links.static[pair][None], v])
            if np.abs(v - v[-1]).max() > 1e-12:
                links.notes.append(f"{st}: {name} was published {len(v)} times with different values; the last is used")
            links.static[pair] = v[-1]
            links.source[pair] = (st, len(v))
    return links


def _no_chain(bag: Path, topics_read: list[str], start: str, goal: str, links: TfLinks) -> str:
    """One line: no path between the frames, with the frames and pairs seen, to choose --tf-frames from."""
    pairs = sorted(links.source.items(), key=lambda kv: (kv[0] in links.static, -kv[1][1], kv[0]))
    frames = sorted({f for pair in links.source for f in pair})
    unseen = [f for f in (start, goal) if f not in frames]
    listed = ", ".join(
        f"{p} -> {c} ({t}, {'static' if (p, c) in links.static else f'{n} transforms'})" for (p, c), (t, n) in pairs
    )
    return (
        f"{bag}: no chain of transforms joins {start} and {goal} on {' and '.join(topics_read)}"
        + (f" ({' and '.join(unseen)} {'is' if len(unseen) == 1 else 'are'} on none of them)" if unseen else "")
        + f"; frames seen: {', '.join(frames) or 'none'}; parent -> child pairs: {listed or 'none'}. Choose "
        "--tf-frames PARENT CHILD among these frames (python -m gyrodenoise.data.from_bag BAG --list)"
    )


def _covered(streams: dict[tuple[str, str], Stream], ref: Step, at: np.ndarray) -> tuple[np.ndarray, list[str], dict]:
    """Which stamps of the reference link every other moving link covers; notes and counts of those dropped."""
    outside_any, gap_any, notes = np.zeros(len(at), bool), np.zeros(len(at), bool), []
    for pair, s in streams.items():
        if pair == ref.pair:
            continue
        outside, in_gap = coverage(s.t_ns, at)
        name = f"{pair[0]} -> {pair[1]}"
        if n := int(outside.sum()):
            notes.append(
                f"{n} of {len(at)} stamps of {ref} lie outside the time {name} covers ({s.t_ns[0]} to {s.t_ns[-1]} "
                "ns) and were dropped"
            )
        if n := int(in_gap.sum()):
            notes.append(
                f"{n} of {len(at)} stamps of {ref} fall in gaps of {name} longer than {MAX_GAP_FACTOR:g}x its median "
                "period and were dropped (interpolation would invent the motion there)"
            )
        outside_any |= outside
        gap_any |= in_gap
    counts = {
        "dropped_outside_coverage": int(outside_any.sum()),
        "dropped_in_gaps": int((gap_any & ~outside_any).sum()),
    }
    return ~(outside_any | gap_any), notes, counts


def _link_at(
    step: Step, links: TfLinks, streams: dict[tuple[str, str], Stream], ref: Step, at: np.ndarray, bag: Path
) -> tuple[Rotation, np.ndarray]:
    """One link of the path as (R, t): a constant, the reference link's own samples, or another link at `at`."""
    if step.pair in links.static:
        v = links.static[step.pair]
        where = f"{bag}: {links.source[step.pair][0]} {step}"
        return _unit_rotations(v[None, 3:], np.zeros(1, np.int64), where)[0], v[:3]
    s = streams[step.pair]
    rot = _unit_rotations(s.values[:, 3:], s.t_ns, f"{bag}: {s.topic}")
    if step.pair == ref.pair:
        keep = np.isin(s.t_ns, at)
        return rot[keep], s.values[keep, :3]
    return resample(s.t_ns, rot, s.values[:, :3], at)


def read_tf_chain(
    bag: Path, topic: str, tf_frames: tuple[str, str] | None, stamp: str, static_topics: list[str]
) -> tuple[Stream, dict]:
    """The pose of frame CHILD in frame PARENT (`tf_frames`) through the chain of links that joins them on `topic`
    (moving) and `static_topics` (constant), a link used against its direction inverted. Moving links other than the
    one with the most transforms (the first of those) are interpolated at its stamps; stamps that another moving link
    does not cover are dropped, with a note. Returns the Stream and the chain's record for bag_import.json."""
    if tf_frames is None:
        raise BagError(f"{bag}: {topic} holds transforms of several frames: choose a pair, {_tf_hint(bag, topic)}")
    start, goal = (_frame(f) for f in tf_frames)
    if start == goal:
        raise BagError(f"--tf-frames {start} {goal}: the same frame twice; give the world frame, then the body's")
    links = read_tf_links(bag, topic, static_topics)
    path = find_path([*links.moving, *links.static], start, goal)
    topics_read = list(dict.fromkeys([topic, *static_topics]))
    if path is None:
        raise BagError(_no_chain(bag, topics_read, start, goal, links))
    frames = path_frames(path, start)
    moving = [s for s in path if s.pair in links.moving]
    if not moving:
        raise BagError(
            f"{bag}: {start} -> {goal} is joined by static transforms only ({' -> '.join(frames)}, on "
            f"{' and '.join(topics_read)}): no motion to use as ground truth; choose frames joined by a moving link of "
            "/tf, such as the world and the body that a motion-capture system tracks (see --list)"
        )
    streams = {s.pair: as_stream(bag, f"{topic} {s}", *links.moving[s.pair], stamp) for s in moving}
    ref = max(moving, key=lambda s: len(streams[s.pair].t_ns))  # max() keeps the first of equals
    keep, notes, counts = _covered(streams, ref, streams[ref.pair].t_ns)
    at = streams[ref.pair].t_ns[keep]
    if not len(at):
        spans = ", ".join(f"{p} -> {c} {s.t_ns[0]} to {s.t_ns[-1]} ns" for (p, c), s in streams.items())
        raise BagError(
            f"{bag}: the moving links of {start} -> {goal} never cover the same instants ({spans}): no pose can be "
            "composed; check that they were recorded together, and --stamp"
        )
    rot, trans = compose([_link_at(s, links, streams, ref, at, bag) for s in path], [s.inverted for s in path])
    out = Stream(topic, at, np.column_stack([trans, rot.as_quat()]))
    out.notes = [n for s in streams.values() for n in s.notes] + [f"{topic} {start} -> {goal}: {n}" for n in notes]
    out.notes += links.notes
    chain = {
        "frames": frames,
        "links": [
            {
                "parent": s.parent,
                "child": s.child,
                "static": s.pair in links.static,
                "inverted": s.inverted,
                "topic": links.source[s.pair][0],
                "transforms": links.source[s.pair][1],
            }
            for s in path
        ],
        "stamps_from": str(ref),
        **counts,
    }
    return out, chain


def describe_chain(chain: dict) -> str:
    """The chain in words for the printed summary: frames, which links are static or inverted, whose stamps."""
    static = [f"{k['parent']} -> {k['child']}" for k in chain["links"] if k["static"]]
    inverted = [f"{k['parent']} -> {k['child']}" for k in chain["links"] if k["inverted"]]
    parts = [" -> ".join(chain["frames"])]
    parts += [f"static: {', '.join(static)}"] if static else []
    parts += [f"inverted: {', '.join(inverted)}"] if inverted else []
    parts.append(f"stamps of {chain['stamps_from']}")
    dropped = chain["dropped_outside_coverage"] + chain["dropped_in_gaps"]
    parts += [f"{dropped} stamps dropped where another link had no data"] if dropped else []
    return "; ".join(parts)


def _unit_rotations(q: np.ndarray, t_ns: np.ndarray, what: str) -> Rotation:
    """Quaternions x, y, z, w as Rotations; a row far from unit length is an error naming `what` and its stamp."""
    norm, k, count = quaternion_norms(q)
    if k is not None:
        raise BagError(
            f"{what}: {count} orientations are not unit quaternions (|q| = {norm[k]:.3g} at {t_ns[k]} ns; "
            "a zero quaternion means no pose): remove those messages or record the ground truth without them"
        )
    return Rotation.from_quat(q / norm[:, None])


def body_to_imu(gt: Stream, imu_in_body: Rotation, bag: Path | None = None) -> np.ndarray:
    """Ground-truth columns of the IMU's own orientation: R_world_imu = R_world_body R_body_imu. `bag` names the
    file in an error."""
    rot = _unit_rotations(gt.values[:, 3:], gt.t_ns, f"{bag}: {gt.topic}" if bag else gt.topic) * imu_in_body
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


def _tf_options(
    bag: Path, found: list[tuple[str, str, int]], gt_topic: str | None, no_gt: bool, tf_frames: tuple[str, str] | None
) -> str | None:
    """The ground-truth topic --tf-frames reads: --gt-topic, else the bag's only topic of moving transforms."""
    if tf_frames is None:
        return gt_topic
    if no_gt:
        raise BagError("--tf-frames chooses a ground truth and --no-gt writes none: give one of them")
    types = {t: ty for t, ty, _ in found}
    if gt_topic is not None:
        if gt_topic in types and types[gt_topic] != TF_TYPE:
            raise BagError(
                f"--tf-frames goes with a {TF_TYPE} --gt-topic such as /tf; {gt_topic} is a {types[gt_topic]}: drop "
                "--tf-frames to read it as the pose"
            )
        return gt_topic
    tf = [t for t, ty, _ in found if ty == TF_TYPE and not is_static_tf(t)]
    if len(tf) != 1:
        what = f"several ({', '.join(tf)}): name one with --gt-topic" if tf else "none (see --list)"
        raise BagError(
            f"{bag}: --tf-frames reads a {TF_TYPE} topic of moving transforms such as /tf; the bag has {what}"
        )
    return tf[0]


def _read_gt(
    bag: Path, found: list[tuple[str, str, int]], gt_topic: str, stamp: str, tf_frames: tuple[str, str] | None
) -> tuple[Stream, dict | None]:
    """The ground-truth stream, and for a transform topic the chain's record (None for a pose topic)."""
    types = {t: ty for t, ty, _ in found}
    if types[gt_topic] != TF_TYPE:
        return read_stream(bag, gt_topic, types[gt_topic], stamp), None
    static_topics = [t for t, ty, _ in found if ty == TF_TYPE and is_static_tf(t)]
    return read_tf_chain(bag, gt_topic, tf_frames, stamp, static_topics)


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
    gt_topic = _tf_options(bag, found, gt_topic, no_gt, tf_frames)
    imu_topic, gt_topic = choose_topics(bag, found, imu_topic, gt_topic, no_gt)
    types = {t: ty for t, ty, _ in found}
    imu = read_stream(bag, imu_topic, IMU_TYPE, stamp)
    imu.values[:, :3] *= GYRO_UNITS[gyro_unit]
    gt, chain = _read_gt(bag, found, gt_topic, stamp, tf_frames) if gt_topic else (None, None)
    imu_in_body = Rotation.from_quat(imu_in_body_xyzw)
    summary = {
        "bag": portable_path(bag),
        "imu_topic": imu_topic,
        "gyro_unit_in_bag": gyro_unit,
        "gt_topic": gt_topic,
        "gt_type": types.get(gt_topic),
        "tf_frames": list(tf_frames) if chain else None,
        "tf_chain": chain,
        "stamp": stamp,
        "imu_messages": len(imu.t_ns),
        "imu_rate_hz": float(1e9 / np.median(np.diff(imu.t_ns))) if len(imu.t_ns) > 1 else None,
        "gt_messages": len(gt.t_ns) if gt else 0,
        "imu_in_body_xyzw": list(imu_in_body.as_quat()),
        "gt_time_offset_s": gt_time_offset_s,
        "notes": imu.notes + (gt.notes if gt else []),
    }
    if gt is None:
        tf = [t for t, ty, _ in found if ty == TF_TYPE and not is_static_tf(t)]
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
        body_to_imu(gt, imu_in_body, bag) if gt else None,
        extra_files={IMPORT_RECORD: json.dumps(summary, indent=2) + "\n"},
    )
    try:
        warnings_found, advice = check_written(folder, imu_topic, gt is not None, imu_in_body)
    except DataFormatError as e:  # e.g. a gyro in deg/s: leave no sequence that looks usable
        shutil.rmtree(folder, ignore_errors=True)
        raise BagError(f"{e} ({folder} was not kept)") from None
    summary.update(data_warnings=warnings_found, advice=advice)  # kept with the data, not only printed
    atomic.write_text(folder / IMPORT_RECORD, json.dumps(summary, indent=2) + "\n")
    summary["output"] = str(folder)
    return summary


def _quat(text: list[str]) -> tuple[float, float, float, float]:
    q = np.asarray([float(x) for x in text])
    n = np.linalg.norm(q)
    if abs(n - 1.0) > QUAT_NORM_TOL:
        raise BagError(f"--imu-in-body {' '.join(text)}: |q| = {n:.4g}, not a unit quaternion (x y z w)")
    return tuple(q / n)


def _print_list(bag: Path) -> None:
    any_tf = False
    for t, ty, n in topics(bag):
        static = ty == TF_TYPE and is_static_tf(t)
        kind = "IMU" if ty == IMU_TYPE else "pose" if ty in POSE_TYPES else "transforms" if ty == TF_TYPE else ""
        print(f"{t}\t{ty}\t{n}\t{'static ' if static else ''}{kind}")
        if ty == TF_TYPE:
            any_tf = True
            for (parent, child), k in sorted(tf_pairs(bag, t).items()):
                print(f"\t{parent} -> {child}\t{k}\tstatic" if static else f"\t--tf-frames {parent} {child}\t{k}")
    if any_tf:
        print(
            "--tf-frames PARENT CHILD also takes two frames joined by a chain of these links (static ones composed "
            "in, a link used against its direction inverted), if at least one link moves"
        )


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m gyrodenoise.data.from_bag",
        description="Write a ROS bag's IMU topic (and a ground-truth pose topic) as one sequence in the ASL layout "
        "that dataset=asl_folder trains on and gyrodenoise-correct corrects.",
        epilog='Needs pip install "gyrodenoise[rosbag]". Then: python -m gyrodenoise.train dataset=asl_folder '
        "dataset.root=ROOT 'dataset.train_seqs=[NAME,...]' ...",
    )
    ap.add_argument("bag", type=Path, help="a ROS 1 .bag file, a ROS 2 bag folder (metadata.yaml), or a .mcap file")
    ap.add_argument(
        "--list", action="store_true", help="list the topics (type, messages; /tf and /tf_static: their frame pairs)"
    )
    ap.add_argument("--out", type=Path, help="the sequence folder to write: ROOT/NAME (new, or an earlier import)")
    ap.add_argument("--imu-topic", help="sensor_msgs/Imu topic (default: the only one)")
    ap.add_argument("--gt-topic", help="pose topic of the ground truth (default: the only one, if any)")
    ap.add_argument(
        "--tf-frames",
        nargs=2,
        metavar=("PARENT", "CHILD"),
        help="ground truth from transforms (--gt-topic, default the bag's /tf): the pose of CHILD in PARENT, composed "
        "along the chain of /tf and /tf_static links that joins them (a link used backwards is inverted; moving "
        "links are interpolated at the stamps of the one with the most transforms, stamps another does not cover "
        "are dropped with a note)",
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
    if (chain := s["tf_chain"]) and (len(chain["links"]) > 1 or chain["links"][0]["inverted"]):
        gt += f" {chain['frames'][0]} -> {chain['frames'][-1]} (chain {describe_chain(chain)})"
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
