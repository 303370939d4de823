"""ROS bags (ROS 1 and ROS 2, written here with rosbags' own writers) imported as ASL sequences."""

from __future__ import annotations

import json
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from gyrodenoise.data import from_bag
from gyrodenoise.data.readers import read_groundtruth, read_imu
from gyrodenoise.sim import handheld_trajectory, simulate_imu

rosbags = pytest.importorskip("rosbags", reason="pip install 'gyrodenoise[rosbag]' (in the dev extra) to read bags")
from rosbags.typesys import Stores, get_typestore  # noqa: E402

TS = get_typestore(Stores.ROS2_HUMBLE)
T = TS.types
MOCAP_STRIDE = 2  # the pose at 100 Hz, the IMU at 200 Hz


@pytest.fixture(scope="module")
def sim():
    return simulate_imu(handheld_trajectory(30.0, seed=5), [], rate_hz=200.0, seed=7)


def _stamp(t_ns: int, frame: str) -> object:
    return T["std_msgs/msg/Header"](
        stamp=T["builtin_interfaces/msg/Time"](sec=int(t_ns // 1_000_000_000), nanosec=int(t_ns % 1_000_000_000)),
        frame_id=frame,
    )


def _vec(v) -> object:
    return T["geometry_msgs/msg/Vector3"](x=float(v[0]), y=float(v[1]), z=float(v[2]))


def _quat(q) -> object:
    return T["geometry_msgs/msg/Quaternion"](x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3]))


def imu_msg(t_ns: int, gyro, acc) -> object:
    return T["sensor_msgs/msg/Imu"](
        header=_stamp(t_ns, "imu"),
        orientation=_quat([0, 0, 0, 1]),
        orientation_covariance=np.r_[-1.0, np.zeros(8)],  # REP 145: no orientation estimate
        angular_velocity=_vec(gyro),
        angular_velocity_covariance=np.zeros(9),
        linear_acceleration=_vec(acc),
        linear_acceleration_covariance=np.zeros(9),
    )


def pose_msg(msgtype: str, t_ns: int, p, q) -> object:
    pose = T["geometry_msgs/msg/Pose"](
        position=T["geometry_msgs/msg/Point"](x=p[0], y=p[1], z=p[2]), orientation=_quat(q)
    )
    if msgtype == "geometry_msgs/msg/PoseStamped":
        return T[msgtype](header=_stamp(t_ns, "world"), pose=pose)
    if msgtype == "geometry_msgs/msg/TransformStamped":
        tf = T["geometry_msgs/msg/Transform"](translation=_vec(p), rotation=_quat(q))
        return T[msgtype](header=_stamp(t_ns, "world"), child_frame_id="body", transform=tf)
    if msgtype == "geometry_msgs/msg/PointStamped":
        return T[msgtype](header=_stamp(t_ns, "world"), point=pose.position)
    if msgtype == "tf2_msgs/msg/TFMessage":  # the body's pose beside another frame's, as a tf tree publishes them
        body = pose_msg("geometry_msgs/msg/TransformStamped", t_ns, p, q)
        other = pose_msg("geometry_msgs/msg/TransformStamped", t_ns, [0.0, 0.0, 1.0], [0.0, 0.0, 0.0, 1.0])
        other.child_frame_id, other.header.frame_id = "camera", "body"
        return T[msgtype](transforms=[other, body])
    raise ValueError(msgtype)


def write_bag(
    path: Path,
    sim,
    ros2: bool = False,
    gt_type: str | None = "geometry_msgs/msg/PoseStamped",
    body_rot: Rotation | None = None,
    gyro_scale: float = 1.0,
    zero_stamps: bool = False,
    extra_imu_topic: bool = False,
    extra_pose_topic: bool = False,
) -> Path:
    """The simulated IMU on /imu0, its pose (of a body rotated by `body_rot` from the IMU) on /mocap."""
    if ros2:
        from rosbags.rosbag2 import Writer

        writer, serialize = Writer(path, version=9), TS.serialize_cdr
    else:
        from rosbags.rosbag1 import Writer

        writer, serialize = Writer(path), TS.serialize_ros1
    R_body = Rotation.from_quat(sim.gt_quat_xyzw) * (body_rot.inv() if body_rot else Rotation.identity())
    with writer as w:
        imu_topics = ["/imu0", "/imu1"] if extra_imu_topic else ["/imu0"]
        imus = [w.add_connection(t, "sensor_msgs/msg/Imu", typestore=TS) for t in imu_topics]
        gts = [w.add_connection("/mocap", gt_type, typestore=TS)] if gt_type else []
        if extra_pose_topic:
            gts.append(w.add_connection("/odom_copy", "geometry_msgs/msg/PoseStamped", typestore=TS))
        for k, t in enumerate(sim.t_ns.tolist()):
            msg = imu_msg(0 if zero_stamps else t, sim.gyro[k] * gyro_scale, sim.acc[k])
            for c in imus:
                w.write(c, t + 2_000_000, serialize(msg, "sensor_msgs/msg/Imu"))  # recorded 2 ms after the sample
            if gts and k % MOCAP_STRIDE == 0:
                for c in gts:
                    m = pose_msg(c.msgtype, t, sim.gt_pos[k], R_body[k].as_quat())
                    w.write(c, t + 5_000_000, serialize(m, c.msgtype))
    return path


@pytest.mark.parametrize(
    "ros2, gt_type", [(False, "geometry_msgs/msg/PoseStamped"), (True, "geometry_msgs/msg/TransformStamped")]
)
def test_bag_becomes_the_same_sequence(tmp_path, sim, ros2, gt_type):
    bag = write_bag(tmp_path / ("rec" if ros2 else "rec.bag"), sim, ros2=ros2, gt_type=gt_type)
    s = from_bag.import_bag(bag, tmp_path / "data" / "rec")
    assert s["imu_topic"] == "/imu0" and s["gt_topic"] == "/mocap" and s["data_warnings"] == [] and s["advice"] == []
    imu = read_imu(tmp_path / "data" / "rec" / "mav0" / "imu0" / "data.csv")
    np.testing.assert_array_equal(imu.t_ns, sim.t_ns)  # header stamps, exact
    np.testing.assert_array_equal(imu.gyro, sim.gyro)  # float64 all the way (ROS stores float64)
    np.testing.assert_array_equal(imu.acc, sim.acc)
    gt = read_groundtruth(tmp_path / "data" / "rec" / "mav0" / "state_groundtruth_estimate0" / "data.csv")
    np.testing.assert_array_equal(gt.t_ns, sim.t_ns[::MOCAP_STRIDE])
    err = Rotation.from_quat(gt.quat_xyzw) * Rotation.from_quat(sim.gt_quat_xyzw[::MOCAP_STRIDE]).inv()
    assert err.magnitude().max() < 1e-12
    meta = json.loads((tmp_path / "data" / "rec" / "bag_import.json").read_text())
    assert meta["imu_messages"] == len(sim.t_ns) and meta["gt_messages"] == len(gt.t_ns) and meta["stamp"] == "header"


def test_record_stamps_and_listing(tmp_path, sim, capsys):
    bag = write_bag(tmp_path / "rec.bag", sim)
    assert from_bag.main([str(bag), "--list"]) == 0
    out = capsys.readouterr().out
    assert "/imu0\tsensor_msgs/msg/Imu\t" in out and "\tIMU" in out and "/mocap\tgeometry_msgs/msg/PoseStamped" in out
    from_bag.import_bag(bag, tmp_path / "r", stamp="record")
    imu = read_imu(tmp_path / "r" / "mav0" / "imu0" / "data.csv")
    np.testing.assert_array_equal(imu.t_ns, sim.t_ns + 2_000_000)


def test_imu_rotated_in_the_mocap_body(tmp_path, sim, capsys):
    """A marker set rotated from the IMU: the import advises the rotation it fits; with it, the truth is the IMU's."""
    body = Rotation.from_euler("zyx", [90, 0, 20], degrees=True)  # the IMU's orientation in the marker body
    bag = write_bag(tmp_path / "rec.bag", sim, body_rot=body)
    assert from_bag.main([str(bag), "--out", str(tmp_path / "a")]) == 0
    cap = capsys.readouterr()
    assert "deg away from the pose's body axes" in cap.out and "away from the ground truth's body axes" in cap.err
    quat = cap.out.split("--imu-in-body ")[1].split()[:4]
    assert "--imu-in-body " + " ".join(quat) + " --overwrite" in cap.out  # the rerun as printed replaces the import
    fitted = Rotation.from_quat([float(x) for x in quat])
    assert (fitted * body.inv()).magnitude() < np.radians(1.0)
    record = json.loads((tmp_path / "a" / "bag_import.json").read_text())  # what was printed is kept with the data
    assert any("away from the ground truth's body axes" in w for w in record["data_warnings"])
    assert len(record["advice"]) == 1 and "--imu-in-body " + " ".join(quat) in record["advice"][0]
    s = from_bag.import_bag(bag, tmp_path / "b", imu_in_body_xyzw=tuple(body.as_quat()))
    assert s["data_warnings"] == [] and s["advice"] == []
    gt = read_groundtruth(tmp_path / "b" / "mav0" / "state_groundtruth_estimate0" / "data.csv")
    err = Rotation.from_quat(gt.quat_xyzw) * Rotation.from_quat(sim.gt_quat_xyzw[::MOCAP_STRIDE]).inv()
    assert err.magnitude().max() < 1e-9


def test_imu_only_bag_is_corrected_by_gyrodenoise_correct(tmp_path, sim):
    bag = write_bag(tmp_path / "rec.bag", sim, gt_type=None)
    s = from_bag.import_bag(bag, tmp_path / "rec")
    assert s["gt_topic"] is None and any("IMU only" in n for n in s["notes"])
    assert not (tmp_path / "rec" / "mav0" / "state_groundtruth_estimate0").exists()
    from gyrodenoise.data.imu_csv import read_imu_csv

    assert len(read_imu_csv(tmp_path / "rec" / "mav0" / "imu0" / "data.csv").t_ns) == len(sim.t_ns)


def test_errors_name_the_topic_and_what_to_do(tmp_path, sim, capsys):
    two = write_bag(tmp_path / "two.bag", sim, extra_imu_topic=True, extra_pose_topic=True)
    with pytest.raises(from_bag.BagError, match=r"2 sensor_msgs/Imu topics: /imu0, /imu1; name one with --imu-topic"):
        from_bag.import_bag(two, tmp_path / "x")
    with pytest.raises(from_bag.BagError, match=r"several pose topics \(/mocap, /odom_copy\); name the ground truth"):
        from_bag.import_bag(two, tmp_path / "x", imu_topic="/imu0")
    with pytest.raises(from_bag.BagError, match=r"--imu-topic /mocap is a geometry_msgs/msg/PoseStamped"):
        from_bag.import_bag(two, tmp_path / "x", imu_topic="/mocap")
    assert from_bag.import_bag(two, tmp_path / "x", imu_topic="/imu1", no_gt=True)["gt_topic"] is None

    point = write_bag(tmp_path / "point.bag", sim, gt_type="geometry_msgs/msg/PointStamped")
    with pytest.raises(from_bag.BagError, match=r"a position only \(no orientation\)"):
        from_bag.import_bag(point, tmp_path / "y", gt_topic="/mocap")

    zero = write_bag(tmp_path / "zero.bag", sim, zero_stamps=True, gt_type=None)
    with pytest.raises(from_bag.BagError, match=r"have no header stamp \(0\).*--stamp record"):
        from_bag.import_bag(zero, tmp_path / "z")

    assert from_bag.main([str(tmp_path / "x.bag"), "--out", str(tmp_path / "x")]) == 2  # exists
    assert "holds an earlier import; choose another --out or pass --overwrite" in capsys.readouterr().err
    assert from_bag.main([str(tmp_path / "nope.bag"), "--out", str(tmp_path / "n")]) == 2
    assert "no such bag" in capsys.readouterr().err
    (tmp_path / "junk.bag").write_bytes(b"not a bag at all")
    with pytest.raises(from_bag.BagError, match=r"junk.bag: cannot be read as a ROS bag"):
        from_bag.topics(tmp_path / "junk.bag")


def test_gyro_in_deg_per_s_is_refused_and_nothing_left(tmp_path, sim):
    bag = write_bag(tmp_path / "deg.bag", sim, gyro_scale=180.0 / np.pi)
    with pytest.raises(from_bag.BagError, match=r"/imu0: the gyro is 57.3 times .* Rerun with --gyro-unit deg/s"):
        from_bag.import_bag(bag, tmp_path / "deg")
    assert not (tmp_path / "deg").exists()


def test_without_rosbags_the_message_says_what_to_install(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "rosbags.highlevel", None)  # import fails as if not installed
    with pytest.raises(from_bag.BagError, match=r'pip install "gyrodenoise\[rosbag\]"'):
        from_bag.topics(tmp_path / "any.bag")


def test_a_tf_topic_gives_the_pose_of_one_frame_pair(tmp_path, sim, capsys):
    bag = write_bag(tmp_path / "tf.bag", sim, gt_type="tf2_msgs/msg/TFMessage")
    assert from_bag.main([str(bag), "--list"]) == 0
    out = capsys.readouterr().out
    assert (
        "/mocap\ttf2_msgs/msg/TFMessage" in out
        and "--tf-frames world body\t" in out
        and "--tf-frames body camera" in out
    )
    s = from_bag.import_bag(bag, tmp_path / "no_pose")  # /tf is no pose topic by itself: said, not passed over
    assert s["gt_topic"] is None and any("--gt-topic /mocap --tf-frames PARENT CHILD" in n for n in s["notes"])
    with pytest.raises(from_bag.BagError, match=r"choose a pair, --tf-frames PARENT CHILD \(pairs there"):
        from_bag.import_bag(bag, tmp_path / "a", gt_topic="/mocap")
    no_chain = r"no chain of transforms joins world and imu on /mocap \(imu is on none.*world -> body"
    with pytest.raises(from_bag.BagError, match=no_chain):
        from_bag.import_bag(bag, tmp_path / "a", gt_topic="/mocap", tf_frames=("world", "imu"))
    s = from_bag.import_bag(bag, tmp_path / "a", gt_topic="/mocap", tf_frames=("/world", "body"))
    assert s["data_warnings"] == [] and s["gt_messages"] == len(sim.t_ns[::MOCAP_STRIDE])
    gt = read_groundtruth(tmp_path / "a" / "mav0" / "state_groundtruth_estimate0" / "data.csv")
    err = Rotation.from_quat(gt.quat_xyzw) * Rotation.from_quat(sim.gt_quat_xyzw[::MOCAP_STRIDE]).inv()
    assert err.magnitude().max() < 1e-12


def test_out_replaces_only_an_earlier_import(tmp_path, sim):
    """--overwrite deleted whatever --out named: a folder of sequences, even the folder holding the bag (an
    independent check of the importer)."""
    (tmp_path / "bags").mkdir()
    bag = write_bag(tmp_path / "bags" / "rec.bag", sim)
    data = tmp_path / "data"
    (data / "seqA" / "mav0").mkdir(parents=True)
    with pytest.raises(from_bag.BagError, match=r"is not a sequence this command wrote .* give ROOT/NAME"):
        from_bag.import_bag(bag, data, overwrite=True)
    assert (data / "seqA" / "mav0").is_dir()
    with pytest.raises(from_bag.BagError, match=r"holds the bag itself"):
        from_bag.import_bag(bag, tmp_path / "bags", overwrite=True)
    assert bag.is_file()
    (tmp_path / "afile").write_text("x")
    with pytest.raises(from_bag.BagError, match=r"afile is a file"):
        from_bag.import_bag(bag, tmp_path / "afile", overwrite=True)
    (data / "rec").mkdir()  # an empty folder is a new one
    from_bag.import_bag(bag, data / "rec")
    with pytest.raises(FileExistsError, match=r"holds an earlier import"):
        from_bag.import_bag(bag, data / "rec")
    assert from_bag.import_bag(bag, data / "rec", overwrite=True, stamp="record")["stamp"] == "record"


def test_duplicates_damage_and_folders_without_metadata(tmp_path, sim):
    bag = write_bag(tmp_path / "rec.bag", sim)
    twice = tmp_path / "twice.bag"  # every 100th IMU message recorded twice
    from rosbags.rosbag1 import Writer

    with Writer(twice) as w:
        c = w.add_connection("/imu0", "sensor_msgs/msg/Imu", typestore=TS)
        for k, t in enumerate(sim.t_ns.tolist()):
            data = TS.serialize_ros1(imu_msg(t, sim.gyro[k], sim.acc[k]), "sensor_msgs/msg/Imu")
            for _ in range(2 if k % 100 == 0 else 1):
                w.write(c, t, data)
    s = from_bag.import_bag(twice, tmp_path / "t")
    assert s["imu_messages"] == len(sim.t_ns) and any(
        "recorded twice (same stamp, same values) kept once" in n for n in s["notes"]
    )

    cut = tmp_path / "cut.bag"  # a recording stopped mid-write
    cut.write_bytes(bag.read_bytes()[: bag.stat().st_size * 2 // 3])
    with pytest.raises(from_bag.BagError, match=r"cut.bag: .*(damaged or cut short|cannot be read).*rosbag reindex"):
        from_bag.import_bag(cut, tmp_path / "c")

    ros2 = write_bag(tmp_path / "r2", sim, ros2=True)
    loose = tmp_path / "loose"
    loose.mkdir()
    for f in ros2.iterdir():
        if f.suffix == ".db3":
            shutil.copy(f, loose / f.name)
    with pytest.raises(
        from_bag.BagError, match=r"needs its metadata.yaml, and this one has none \(it holds \['r2.*db3'\]\)"
    ):
        from_bag.topics(loose)


def test_a_gyro_in_deg_per_s_is_read_with_gyro_unit(tmp_path, sim):
    bag = write_bag(tmp_path / "deg.bag", sim, gyro_scale=180.0 / np.pi)
    s = from_bag.import_bag(bag, tmp_path / "deg", gyro_unit="deg/s")
    assert s["data_warnings"] == [] and s["gyro_unit_in_bag"] == "deg/s"
    np.testing.assert_allclose(read_imu(tmp_path / "deg" / "mav0" / "imu0" / "data.csv").gyro, sim.gyro, atol=1e-12)


def test_a_pose_that_is_not_a_unit_quaternion_names_the_bag(tmp_path, sim):
    """The error named the topic only: with several bags imported in a loop, which one was it?"""
    from rosbags.rosbag1 import Writer

    bag = tmp_path / "scaled.bag"
    with Writer(bag) as w:
        c = w.add_connection("/mocap", "geometry_msgs/msg/PoseStamped", typestore=TS)
        i = w.add_connection("/imu0", "sensor_msgs/msg/Imu", typestore=TS)
        for k, t in enumerate(sim.t_ns[:2000].tolist()):
            w.write(i, t, TS.serialize_ros1(imu_msg(t, sim.gyro[k], sim.acc[k]), "sensor_msgs/msg/Imu"))
            q = 2.0 * sim.gt_quat_xyzw[k]  # a quaternion of norm 2: no orientation
            m = pose_msg("geometry_msgs/msg/PoseStamped", t, sim.gt_pos[k], q)
            w.write(c, t, TS.serialize_ros1(m, "geometry_msgs/msg/PoseStamped"))
    with pytest.raises(from_bag.BagError, match=rf"^{bag}: /mocap: 2000 orientations are not unit quaternions"):
        from_bag.import_bag(bag, tmp_path / "out")
    assert not (tmp_path / "out").exists()
