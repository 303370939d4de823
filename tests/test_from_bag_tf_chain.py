"""Ground truth from a chain of /tf and /tf_static links (bags written here with rosbags' own writers)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from gyrodenoise.data import from_bag
from gyrodenoise.data.readers import read_groundtruth
from gyrodenoise.sim import handheld_trajectory, simulate_imu

pytest.importorskip("rosbags", reason="pip install 'gyrodenoise[rosbag]' (in the dev extra) to read bags")
from test_from_bag import TS, T, _quat, _stamp, _vec, imu_msg  # noqa: E402

TF = "tf2_msgs/msg/TFMessage"
IMU_IN_BODY = Rotation.from_euler("zyx", [90, -10, 180], degrees=True)  # the IMU's orientation in the body
IMU_AT = np.array([0.05, -0.02, 0.10])  # the IMU's origin in the body frame (m)


@pytest.fixture(scope="module")
def sim():
    return simulate_imu(handheld_trajectory(20.0, seed=3), [], rate_hz=200.0, seed=4)


def tf_msg(t_ns: int, links: list[tuple[str, str, np.ndarray, np.ndarray]]) -> object:
    """A TFMessage of (parent, child, translation, quaternion xyzw) links, all stamped `t_ns`."""
    return T[TF](
        transforms=[
            T["geometry_msgs/msg/TransformStamped"](
                header=_stamp(t_ns, parent),
                child_frame_id=child,
                transform=T["geometry_msgs/msg/Transform"](translation=_vec(p), rotation=_quat(q)),
            )
            for parent, child, p, q in links
        ]
    )


def write_tf_bag(
    path: Path, sim, moving: dict[str, list], static: list, ros2: bool = True, static_later: list | None = None
) -> Path:
    """The IMU on /imu0; `moving`: {topic: [(t_ns, links), ...]}; `static`: links on /tf_static, once at the start
    (and `static_later` once more in the middle)."""
    if ros2:
        from rosbags.rosbag2 import Writer

        writer, serialize, latched = Writer(path, version=9), TS.serialize_cdr, {}
    else:
        from rosbags.rosbag1 import Writer

        writer, serialize, latched = Writer(path), TS.serialize_ros1, {"latching": 1}
    with writer as w:
        imu = w.add_connection("/imu0", "sensor_msgs/msg/Imu", typestore=TS)
        if static:
            c = w.add_connection("/tf_static", TF, typestore=TS, **latched)
            w.write(c, int(sim.t_ns[0]), serialize(tf_msg(0, static), TF))  # static transforms: stamp 0 is common
            if static_later:
                w.write(c, int(sim.t_ns[len(sim.t_ns) // 2]), serialize(tf_msg(0, static_later), TF))
        messages = [(int(t), imu, imu_msg(int(t), sim.gyro[k], sim.acc[k])) for k, t in enumerate(sim.t_ns)]
        for topic, stamped in moving.items():
            c = w.add_connection(topic, TF, typestore=TS)
            messages += [(t, c, tf_msg(t, links)) for t, links in stamped]
        for t, c, m in sorted(messages, key=lambda x: x[0]):
            w.write(c, t + 1_000_000, serialize(m, c.msgtype))
    return path


def imu_pose(sim, k):
    return Rotation.from_quat(sim.gt_quat_xyzw[k]), sim.gt_pos[k]


def body_pose(sim, k):
    """world -> body such that world -> body -> imu (IMU_IN_BODY, IMU_AT) is the simulated IMU's pose."""
    r_imu, p_imu = imu_pose(sim, k)
    r_body = r_imu * IMU_IN_BODY.inv()
    return r_body, p_imu - r_body.apply(IMU_AT)


def read_gt(folder: Path):
    return read_groundtruth(folder / "mav0" / "state_groundtruth_estimate0" / "data.csv")


def assert_is_imu_pose(gt, sim, k):
    np.testing.assert_array_equal(gt.t_ns, sim.t_ns[k])
    r, p = imu_pose(sim, k)
    assert (Rotation.from_quat(gt.quat_xyzw) * r.inv()).magnitude().max() < 1e-9
    assert np.abs(gt.pos - p).max() < 1e-9


def mocap_bag(path: Path, sim, ros2: bool = True, imu_first: bool = False) -> Path:
    """world -> body (100 Hz) on /tf, body -> imu on /tf_static (imu -> body if `imu_first`) beside body -> camera."""
    k = np.arange(0, len(sim.t_ns), 2)
    stamped = [(int(sim.t_ns[i]), [("world", "body", body_pose(sim, i)[1], body_pose(sim, i)[0].as_quat())]) for i in k]
    if imu_first:
        r = IMU_IN_BODY.inv()
        static = [("imu", "body", -r.apply(IMU_AT), r.as_quat())]
    else:
        static = [("body", "imu", IMU_AT, IMU_IN_BODY.as_quat())]
    static.append(("body", "camera", np.array([0.1, 0.0, 0.0]), np.array([0.0, 0.0, 0.0, 1.0])))
    return write_tf_bag(path, sim, {"/tf": stamped}, static, ros2=ros2)


@pytest.mark.parametrize("ros2", [True, False])
def test_a_static_link_on_tf_static_is_composed_in(tmp_path, sim, ros2, capsys):
    bag = mocap_bag(tmp_path / ("rec" if ros2 else "rec.bag"), sim, ros2=ros2)
    out = tmp_path / "data" / "rec"
    assert from_bag.main([str(bag), "--out", str(out), "--tf-frames", "world", "imu"]) == 0  # /tf: the only one
    printed = capsys.readouterr()
    assert "poses from /tf world -> imu (chain world -> body -> imu; static: body -> imu; stamps of world -> body)" in (
        printed.out
    )
    assert "warning" not in printed.err
    assert_is_imu_pose(read_gt(out), sim, np.arange(0, len(sim.t_ns), 2))
    meta = json.loads((out / "bag_import.json").read_text())
    chain = meta["tf_chain"]
    assert meta["gt_topic"] == "/tf" and meta["tf_frames"] == ["world", "imu"]
    assert chain["frames"] == ["world", "body", "imu"] and chain["stamps_from"] == "world -> body"
    assert [(k["static"], k["inverted"], k["topic"]) for k in chain["links"]] == [
        (False, False, "/tf"),
        (True, False, "/tf_static"),
    ]
    assert chain["dropped_outside_coverage"] == 0 and chain["dropped_in_gaps"] == 0


def test_a_link_recorded_the_other_way_is_inverted(tmp_path, sim):
    bag = mocap_bag(tmp_path / "rec", sim, imu_first=True)
    s = from_bag.import_bag(bag, tmp_path / "a", gt_topic="/tf", tf_frames=("world", "imu"))
    assert s["data_warnings"] == [] and s["advice"] == []
    assert_is_imu_pose(read_gt(tmp_path / "a"), sim, np.arange(0, len(sim.t_ns), 2))
    links = s["tf_chain"]["links"]
    assert [(k["parent"], k["child"], k["inverted"]) for k in links] == [
        ("world", "body", False),
        ("imu", "body", True),
    ]
    # the whole chain backwards: the world's pose in the IMU frame is the inverse of the IMU's in the world
    s = from_bag.import_bag(bag, tmp_path / "b", tf_frames=("imu", "world"))
    assert s["tf_chain"]["frames"] == ["imu", "body", "world"]
    gt = read_gt(tmp_path / "b")
    k = np.arange(0, len(sim.t_ns), 2)
    r, p = imu_pose(sim, k)
    assert (Rotation.from_quat(gt.quat_xyzw) * r).magnitude().max() < 1e-9
    assert np.abs(gt.pos + r.inv().apply(p)).max() < 1e-9


def drift(t_ns: np.ndarray, t0_ns: int) -> tuple[Rotation, np.ndarray]:
    """map -> odom: a constant-rate turn about a fixed axis and a constant velocity, which SLERP and linear
    interpolation reproduce exactly between samples."""
    t = (t_ns - t0_ns) / 1e9
    rot = Rotation.from_euler("x", 20, degrees=True) * Rotation.from_rotvec(np.outer(t, [0.01, -0.02, 0.03]))
    return rot, np.column_stack([1.0 + 0.02 * t, -0.5 + 0.01 * t, 0.003 * t])


def test_two_moving_links_at_different_rates(tmp_path, sim, capsys):
    """map -> odom at 20 Hz (starting late, ending early, with a 1 s gap), odom -> base_link at 100 Hz, base_link ->
    imu static: the chain at base_link's stamps, those map -> odom does not cover dropped and counted."""
    k_base = np.arange(0, len(sim.t_ns), 2)
    k_odom = np.arange(100, len(sim.t_ns) - 100, 10)  # 0.5 s late, 0.5 s early
    k_odom = k_odom[(k_odom < 1000) | (k_odom > 1200)]  # no map -> odom from 5 s to 6 s
    odom_rows = []
    for i in k_odom:
        r, p = drift(sim.t_ns[i : i + 1], int(sim.t_ns[0]))
        odom_rows.append((int(sim.t_ns[i]), [("map", "odom", p[0], r[0].as_quat())]))
    base_rows = []
    for i in k_base:  # odom -> base_link = (map -> odom)^-1 (map -> base_link)
        r_mo, p_mo = drift(sim.t_ns[i : i + 1], int(sim.t_ns[0]))
        r_mb, p_mb = body_pose(sim, i)
        r_ob = r_mo[0].inv() * r_mb
        base_rows.append(
            (int(sim.t_ns[i]), [("odom", "base_link", r_mo[0].inv().apply(p_mb - p_mo[0]), r_ob.as_quat())])
        )
    tf = sorted(odom_rows + base_rows, key=lambda x: x[0])
    static = [("base_link", "imu", IMU_AT, IMU_IN_BODY.as_quat())]
    bag = write_tf_bag(tmp_path / "rec", sim, {"/tf": tf}, static)
    assert from_bag.main([str(bag), "--out", str(tmp_path / "a"), "--tf-frames", "map", "imu"]) == 0
    cap = capsys.readouterr()
    printed = cap.out
    assert "warning" not in cap.err  # the composed truth agrees with the gyro
    t_base, t_odom = sim.t_ns[k_base], sim.t_ns[k_odom]
    inside = (t_base >= t_odom[0]) & (t_base <= t_odom[-1])
    in_gap = (t_base > sim.t_ns[990]) & (t_base < sim.t_ns[1210])
    kept = k_base[inside & ~in_gap]
    assert_is_imu_pose(read_gt(tmp_path / "a"), sim, kept)
    meta = json.loads((tmp_path / "a" / "bag_import.json").read_text())
    chain = meta["tf_chain"]
    assert chain["frames"] == ["map", "odom", "base_link", "imu"] and chain["stamps_from"] == "odom -> base_link"
    assert chain["dropped_outside_coverage"] == (~inside).sum() and chain["dropped_in_gaps"] == in_gap.sum()
    assert meta["gt_messages"] == len(kept)
    assert f"{(~inside).sum()} of {len(k_base)} stamps of odom -> base_link lie outside the time map -> odom" in (
        " ".join(meta["notes"])
    )
    assert f"{in_gap.sum()} of {len(k_base)} stamps of odom -> base_link fall in gaps of map -> odom" in printed
    assert "stamps of odom -> base_link" in printed and f"{len(k_base) - len(kept)} stamps dropped" in printed


def test_errors_name_the_frames_and_what_to_do(tmp_path, sim, capsys):
    bag = mocap_bag(tmp_path / "rec", sim)
    assert from_bag.main([str(bag), "--list"]) == 0
    listed = capsys.readouterr().out
    assert "/tf_static\ttf2_msgs/msg/TFMessage\t1\tstatic transforms" in listed
    assert "\tbody -> imu\t1\tstatic" in listed and "\t--tf-frames world body\t" in listed
    with pytest.raises(from_bag.BagError, match=r"body -> imu is joined by static transforms only .*no motion"):
        from_bag.import_bag(bag, tmp_path / "a", tf_frames=("body", "imu"))
    with pytest.raises(from_bag.BagError, match=r"static transforms only \(camera -> body -> imu"):
        from_bag.import_bag(bag, tmp_path / "a", tf_frames=("camera", "imu"))
    no_chain = (
        r"no chain of transforms joins world and vicon/imu on /tf and /tf_static \(vicon/imu is on none of them\); "
        r"frames seen: body, camera, imu, world; parent -> child pairs: world -> body \(/tf, \d+ transforms\), "
        r"body -> camera \(/tf_static, static\), body -> imu \(/tf_static, static\)\. Choose --tf-frames"
    )
    with pytest.raises(from_bag.BagError, match=no_chain):
        from_bag.import_bag(bag, tmp_path / "a", tf_frames=("world", "vicon/imu"))
    with pytest.raises(from_bag.BagError, match=r"--tf-frames world world: the same frame twice"):
        from_bag.import_bag(bag, tmp_path / "a", tf_frames=("world", "world"))
    with pytest.raises(
        from_bag.BagError, match=r"--tf-frames goes with a tf2_msgs/msg/TFMessage --gt-topic .*/imu0 is a"
    ):
        from_bag.import_bag(bag, tmp_path / "a", gt_topic="/imu0", tf_frames=("world", "imu"))
    with pytest.raises(from_bag.BagError, match=r"--tf-frames chooses a ground truth and --no-gt writes none"):
        from_bag.import_bag(bag, tmp_path / "a", no_gt=True, tf_frames=("world", "imu"))
    assert from_bag.main([str(bag), "--out", str(tmp_path / "a"), "--tf-frames", "world", "nowhere"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no chain of transforms joins world and nowhere" in err
    assert not (tmp_path / "a").exists()

    apart = [(int(sim.t_ns[i]), [("map", "odom", IMU_AT, [0, 0, 0, 1])]) for i in range(0, 100, 10)]
    apart += [(int(sim.t_ns[i]), [("odom", "base_link", IMU_AT, [0, 0, 0, 1])]) for i in range(200, 400, 2)]
    bag = write_tf_bag(tmp_path / "apart", sim, {"/tf": apart}, [])  # and no /tf_static
    with pytest.raises(from_bag.BagError, match=r"moving links of map -> base_link never cover the same instants"):
        from_bag.import_bag(bag, tmp_path / "a", tf_frames=("map", "base_link"))


def test_static_only_bags_and_a_static_link_published_again(tmp_path, sim):
    static = [("body", "imu", IMU_AT, IMU_IN_BODY.as_quat())]
    only_static = write_tf_bag(tmp_path / "static", sim, {}, static)
    with pytest.raises(from_bag.BagError, match=r"topic of moving transforms such as /tf; the bag has none"):
        from_bag.import_bag(only_static, tmp_path / "a", tf_frames=("body", "imu"))
    with pytest.raises(from_bag.BagError, match=r"static transforms only \(body -> imu, on /tf_static\)"):
        from_bag.import_bag(only_static, tmp_path / "a", gt_topic="/tf_static", tf_frames=("body", "imu"))

    k = np.arange(0, len(sim.t_ns), 2)
    stamped = [(int(sim.t_ns[i]), [("world", "body", body_pose(sim, i)[1], body_pose(sim, i)[0].as_quat())]) for i in k]
    moved = [("body", "imu", IMU_AT + 0.01, IMU_IN_BODY.as_quat())]  # re-calibrated mid-recording
    bag = write_tf_bag(tmp_path / "rec", sim, {"/tf": stamped}, static, static_later=moved)
    s = from_bag.import_bag(bag, tmp_path / "b", tf_frames=("world", "imu"))
    assert "/tf_static: body -> imu was published 2 times with different values; the last is used" in s["notes"]
    gt = read_gt(tmp_path / "b")
    assert (
        np.abs(
            gt.pos
            - (
                sim.gt_pos[k]
                + Rotation.from_quat(sim.gt_quat_xyzw[k]).apply(IMU_IN_BODY.inv().apply([0.01, 0.01, 0.01]))
            )
        ).max()
        < 1e-9
    )
