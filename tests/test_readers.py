"""Reader validation: every bad input names the file, the line or column, and what is wrong."""

import re
from pathlib import Path

import numpy as np
import pytest

from gyrodenoise.data.cache import load_sequence
from gyrodenoise.data.readers import DataFormatError, DataFormatWarning, read_groundtruth, read_imu
from gyrodenoise.data.sequence import build_sequence

IMU_HEADER = "#timestamp [ns],w_x,w_y,w_z,a_x,a_y,a_z\n"
GT_HEADER = "#timestamp, p_x, p_y, p_z, q_w, q_x, q_y, q_z\n"


def write(path: Path, header: str, rows: list[str]) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(header + "".join(r + "\n" for r in rows))
    return path


def imu_rows(n=50, t0=1_000_000_000, dt=5_000_000):
    return [f"{t0 + k * dt},0.01,0.02,0.03,0.1,0.2,9.8" for k in range(n)]


def gt_rows(n=50, t0=1_000_000_000, dt=5_000_000, extra=""):
    return [f"{t0 + k * dt},1,2,3,1,0,0,0{extra}" for k in range(n)]


def test_reads_valid_files_and_extra_gt_columns(tmp_path):
    imu = read_imu(write(tmp_path / "imu.csv", IMU_HEADER, imu_rows()))
    gt = read_groundtruth(write(tmp_path / "gt.csv", GT_HEADER, gt_rows(extra=",0,0,0,0,0,0,0,0,0")))
    assert imu.t_ns.dtype == np.int64 and imu.gyro.shape == (50, 3)
    np.testing.assert_allclose(gt.quat_xyzw[0], [0, 0, 0, 1])  # w,x,y,z on disk -> x,y,z,w inside


def test_missing_file_says_where(tmp_path):
    with pytest.raises(FileNotFoundError, match="imu0/data.csv"):
        read_imu(tmp_path / "mav0" / "imu0" / "data.csv")


def test_wrong_column_count(tmp_path):
    rows = imu_rows()
    rows[3] = "1015000000,0.01,0.02,0.03,0.1,0.2"
    with pytest.raises(DataFormatError, match=r"imu.csv:5: IMU line has 6 columns, expected at least 7"):
        read_imu(write(tmp_path / "imu.csv", IMU_HEADER, rows))


def test_not_a_number_names_line_and_column(tmp_path):
    rows = imu_rows()
    rows[10] = rows[10].replace("0.02", "abc")
    with pytest.raises(DataFormatError, match=r"imu.csv:12: column 3 is 'abc'"):
        read_imu(write(tmp_path / "imu.csv", IMU_HEADER, rows))


@pytest.mark.parametrize("reader", [read_imu, read_groundtruth])
def test_binary_file_names_file_byte_and_layout(tmp_path, reader):
    # a valid first line, then a Latin-1 byte on line 3 (byte offset: header + line 2 + 1)
    rows = (IMU_HEADER + imu_rows(1)[0] + "\n").encode()
    path = tmp_path / "mav0" / "imu0" / "data.csv"
    path.parent.mkdir(parents=True)
    path.write_bytes(rows + b"1\xb9\x00\xff" + bytes(range(256)) * 40)
    with pytest.raises(DataFormatError, match=rf"data.csv:3: byte 0xb9 at offset {len(rows) + 1} is not UTF-8") as e:
        reader(path)
    assert "not a UTF-8 text CSV file; expected an ASL" in str(e.value) and "converted to CSV" in str(e.value)
    path.write_bytes(b"\x00" * 64)  # valid UTF-8, but binary
    with pytest.raises(DataFormatError, match=r"data.csv:1: NUL byte \(binary data\)"):
        reader(path)


def test_nan_is_reported_not_dropped(tmp_path):
    rows = imu_rows()
    rows[7] = rows[7].replace("9.8", "nan")
    with pytest.raises(DataFormatError, match=r"imu.csv:9: column 7 .*NaN.*\(1 such line\)"):
        read_imu(write(tmp_path / "imu.csv", IMU_HEADER, rows))


def test_duplicate_timestamp(tmp_path):
    """A stamp repeated with other values is refused, counted (one error per rerun before)."""
    rows = imu_rows()
    rows[5] = rows[4].replace(",0.01,", ",0.05,")
    rows[30] = rows[29].replace(",0.02,", ",0.04,")
    with pytest.raises(DataFormatError, match=r"imu.csv:7: duplicate timestamp .* line 6\) with other values .*2 such"):
        read_imu(write(tmp_path / "imu.csv", IMU_HEADER, rows))


def test_an_exact_repeat_of_a_line_is_kept_once_with_a_warning(tmp_path):
    """A logger that wrote a sample twice (same stamp, same values) stopped training, one error per rerun, while
    gyrodenoise-correct offers --drop-duplicates and the bag import keeps such messages once (own-data
    walkthrough): kept once, named; the line numbers of later messages still point into the file."""
    rows = imu_rows()
    repeated = rows[:5] + [rows[4]] + rows[5:20] + [rows[19], rows[19]] + rows[20:]
    with pytest.warns(DataFormatWarning, match=r"imu.csv:7: 3 IMU lines repeat the line before exactly .*line 6\)"):
        imu = read_imu(write(tmp_path / "imu.csv", IMU_HEADER, repeated))
    clean = read_imu(write(tmp_path / "clean.csv", IMU_HEADER, rows))
    np.testing.assert_array_equal(imu.t_ns, clean.t_ns)
    np.testing.assert_array_equal(imu.gyro, clean.gyro)
    gt = gt_rows()
    gt = gt[:3] + [gt[2]] + gt[3:]
    gt[10] = gt[10][: gt[10].rfind(",1,0,0,0")] + ",0.9,0,0,0"  # file line 12 (header, 3 rows, the repeat, ...)
    with pytest.warns(DataFormatWarning, match=r"gt.csv:5: 1 ground truth line repeats"):
        with pytest.raises(DataFormatError, match=r"gt.csv:12: quaternion"):
            read_groundtruth(write(tmp_path / "gt.csv", GT_HEADER, gt))


def test_non_monotonic_timestamp(tmp_path):
    rows = imu_rows()
    rows[5], rows[6] = rows[6], rows[5]
    with pytest.raises(DataFormatError, match=r"imu.csv:8: timestamp .* goes back in time"):
        read_imu(write(tmp_path / "imu.csv", IMU_HEADER, rows))


def test_non_unit_quaternion(tmp_path):
    rows = gt_rows()
    rows[2] = rows[2][: rows[2].rfind(",1,0,0,0")] + ",0.9,0,0,0"
    with pytest.raises(DataFormatError, match=r"gt.csv:4: quaternion .* norm 0.900000"):
        read_groundtruth(write(tmp_path / "gt.csv", GT_HEADER, rows))


def test_ground_truth_not_overlapping(tmp_path):
    imu = read_imu(write(tmp_path / "imu.csv", IMU_HEADER, imu_rows()))
    gt = read_groundtruth(write(tmp_path / "gt.csv", GT_HEADER, gt_rows(t0=9_000_000_000)))
    with pytest.raises(DataFormatError, match="does not overlap the IMU"):
        build_sequence("x", imu, gt)
    # meeting it at one IMU sample (the truth starts 2 ms before the IMU's last stamp): a one-sample sequence was built
    last = int(imu.t_ns[-1])
    gt = read_groundtruth(write(tmp_path / "gt1.csv", GT_HEADER, gt_rows(t0=last - 2_000_000)))
    with pytest.raises(DataFormatError, match=r"overlaps the IMU .* in 1 IMU sample\(s\) only"):
        build_sequence("x", imu, gt)


@pytest.mark.parametrize(
    ("stamps", "says"),
    [
        (lambda k: 1_700_000_001_000_000 + k * 8_333, "look like µs; write them as integer ns \\(x 1e\\+03\\)"),
        (lambda k: 1_700_000_001 + k, "look like s; write them as integer ns \\(x 1e\\+09\\)"),
        (lambda k: k * 8_333_333, "start near zero"),
    ],
)
def test_a_ground_truth_on_another_clock_says_which(tmp_path, stamps, says):
    """Mocap stamps in µs (or s, or from its own start) beside the IMU's ns said only 'does not overlap' (own-data
    walkthrough)."""
    t0 = 1_700_000_001_000_000_000
    imu = read_imu(write(tmp_path / "imu.csv", IMU_HEADER, imu_rows(n=400, t0=t0)))
    rows = [f"{stamps(k)},1,2,3,1,0,0,0" for k in range(200)]
    gt = read_groundtruth(write(tmp_path / "gt.csv", GT_HEADER, rows))
    with pytest.raises(DataFormatError, match="does not overlap the IMU .*" + says):
        build_sequence("x", imu, gt)


@pytest.mark.parametrize(
    ("stamp", "says"),
    [
        ("1700001000.300002", "stamps in seconds"),
        ("1700001000300.002", "stamps in milli- or microseconds.*ms x 1e6"),  # since 1970 in ms, a phone log's
        ("1700001000300002.5", "stamps in milli- or microseconds.*µs x 1e3"),
        ("1.700001e+18", "write the nanoseconds as integers"),
    ],
)
def test_a_decimal_timestamp_says_what_to_write(tmp_path, stamp, says):
    rows = gt_rows()
    rows[3] = stamp + rows[3][rows[3].index(",") :]
    with pytest.raises(DataFormatError, match=rf"gt.csv:5: column 1 \(timestamp\) is '{re.escape(stamp)}'.*{says}"):
        read_groundtruth(write(tmp_path / "gt.csv", GT_HEADER, rows))


def test_gap_in_ground_truth_is_masked(tmp_path):
    rows = gt_rows(n=200)
    del rows[100:160]  # 0.3 s occlusion
    imu = read_imu(write(tmp_path / "imu.csv", IMU_HEADER, imu_rows(n=200)))
    seq = build_sequence("x", imu, read_groundtruth(write(tmp_path / "gt.csv", GT_HEADER, rows)))
    assert not seq.gt_mask[101:159].any()
    assert seq.gt_mask[:100].all() and seq.gt_mask[160:].all()


def test_cache_rebuilds_when_a_file_changes(tmp_path):
    mav0 = tmp_path / "root" / "seq" / "mav0"
    write(mav0 / "imu0" / "data.csv", IMU_HEADER, imu_rows())
    gt = write(mav0 / "state_groundtruth_estimate0" / "data.csv", GT_HEADER, gt_rows())
    cache = tmp_path / "cache"
    a = load_sequence(tmp_path / "root", "seq", cache_dir=cache)
    assert len(list(cache.glob("*.npz"))) == 1
    b = load_sequence(tmp_path / "root", "seq", cache_dir=cache)
    np.testing.assert_array_equal(a.rot, b.rot)
    write(gt, GT_HEADER, [r.replace(",1,2,3,", ",5,2,3,") for r in gt_rows()])
    c = load_sequence(tmp_path / "root", "seq", cache_dir=cache)
    assert len(list(cache.glob("*.npz"))) == 2 and c.pos[0, 0] == 5


def test_a_cached_sequence_names_the_files_it_was_loaded_from(tmp_path):
    """The cache is keyed by content: the same files under another root hit it, and must be named by that root."""
    import shutil

    mav0 = tmp_path / "a" / "seq" / "mav0"
    write(mav0 / "imu0" / "data.csv", IMU_HEADER, imu_rows())
    write(mav0 / "state_groundtruth_estimate0" / "data.csv", GT_HEADER, gt_rows())
    load_sequence(tmp_path / "a", "seq", cache_dir=tmp_path / "cache")
    shutil.move(tmp_path / "a", tmp_path / "b")
    b = load_sequence(tmp_path / "b", "seq", cache_dir=tmp_path / "cache")
    assert len(list((tmp_path / "cache").glob("*.npz"))) == 1  # a hit
    assert b.meta["imu_file"] == str(tmp_path / "b" / "seq" / "mav0" / "imu0" / "data.csv")
    assert b.meta["gt_file"].startswith(str(tmp_path / "b"))


def test_real_euroc_and_tumvi_sequences(euroc_root, tumvi_root):
    seq = load_sequence(euroc_root, "V1_01_easy", "state_groundtruth_estimate0/data_recomputed_openvins.csv")
    assert abs(seq.rate_hz - 200.0) < 0.1 and seq.gt_mask.all()
    room = load_sequence(tumvi_root, "dataset-room1_512_16")
    assert abs(room.rate_hz - 199.4) < 0.5  # read from the data, not assumed
    assert 0.8 < room.gt_mask.mean() < 1.0  # mocap occlusions masked, not bridged


@pytest.mark.parametrize(
    ("header", "said"),
    [
        ("#t,a_x,a_y,a_z,w_x,w_y,w_z\n", r"imu.csv:1: column 2 is 'a_x' where gyro x is expected.*reorder"),
        ("#t,temperature [C],w_x,w_y,w_z,a_x,a_y\n", r"column 2 is 'temperature \[C\]' where gyro x"),
        (
            "#t,gx [deg/s],gy [deg/s],gz [deg/s],ax [g],ay [g],az [g]\n",
            r"'gx \[deg/s\]' is in deg/s.*pi/180.*'ax \[g\]' is in g",
        ),
        ('#"t","a_x","a_y","a_z","w_x","w_y","w_z"\n', r"column 2 is '\"a_x\"' where gyro x"),  # quoted names
        ("#t,a_x,a_y,a_z,w_x,w_y,w_z\n# end of header\n", r"imu.csv:1: column 2 is 'a_x'"),  # a note below it
        ("#timestamp [us],w_x,w_y,w_z,a_x,a_y,a_z\n", r"timestamps in µs.*integer nanoseconds"),
        # units written into the names, and headers split by tabs or semicolons
        (
            "#time_us,gyro_x_dps,gyro_y_dps,gyro_z_dps,acc_x,acc_y,acc_z\n",
            r"in µs \('time_us'\).*'gyro_x_dps' is in deg/s",
        ),
        ("#t\tgyro_x\tgyro_y\tgyro_z\tacc_x_g\tacc_y_g\tacc_z_g\n", r"'acc_x_g' is in g;.* by 9\.80665"),
        ("#t;a_x;a_y;a_z;w_x;w_y;w_z\n", r"column 2 is 'a_x' where gyro x"),
        ("#t,w_x,w_y,w_z,a_x [mg],a_y [mg],a_z [mg]\n", r"is in mg;.* by 0\.00980665"),
    ],
)
def test_an_imu_header_that_contradicts_the_column_order_or_units_is_refused(tmp_path, header, said):
    with pytest.raises(DataFormatError, match=said):
        read_imu(write(tmp_path / "imu.csv", header, imu_rows()))


def test_imu_headers_that_agree_or_say_nothing_are_read(tmp_path):
    agree = [
        IMU_HEADER,
        "#t,gx,gy,gz,ax,ay,az\n",
        "#t,x,y,z,ax,ay,az\n",
        "#timestamp,omega_x,omega_y,omega_z,alpha_x,alpha_y,alpha_z\n",
        # names other tools write (ROS, MATLAB, phones, aerospace rates)
        "#t,ang_vel_x,ang_vel_y,ang_vel_z,lin_acc_x,lin_acc_y,lin_acc_z\n",
        "#t,AngularVelocity_1,AngularVelocity_2,AngularVelocity_3,Acceleration_1,Acceleration_2,Acceleration_3\n",
        "#t,p_rate,q_rate,r_rate,ax,ay,az\n",
        "#t,rotationRate.x,rotationRate.y,rotationRate.z,userAcceleration.x,userAcceleration.y,userAcceleration.z\n",
        "#timestamp_ns,gyro_x_rad_s,gyro_y_rad_s,gyro_z_rad_s,acc_x_mps2,acc_y_mps2,acc_z_mps2\n",
        "#t\tw_RS_S_x\tw_RS_S_y\tw_RS_S_z\ta_RS_S_x\ta_RS_S_y\ta_RS_S_z\n",
        IMU_HEADER + "# columns: timestamp, gyro x y z, accel x y z\n",  # a note below the header is not the header
    ]
    for header in [*agree, "#c1,c2,c3,c4,c5,c6,c7\n", "", "# a comment\n"]:
        assert len(read_imu(write(tmp_path / "imu.csv", header, imu_rows())).t_ns) == 50, header


def test_a_truth_header_with_the_quaternion_w_last_is_refused(tmp_path):
    header = "#timestamp, p_x, p_y, p_z, q_x, q_y, q_z, q_w\n"
    with pytest.raises(DataFormatError, match=r"gt.csv:1: column 5 is 'q_x' .* stored x, y, z, w: move its w"):
        read_groundtruth(write(tmp_path / "gt.csv", header, gt_rows()))


@pytest.mark.parametrize(("dt", "unit"), [(5_000, "µs"), (5, "ms"), (20_000, "µs")])  # 200 Hz, 200 Hz, 50 Hz
def test_imu_stamps_that_are_not_ns_are_refused(tmp_path, dt, unit):
    with pytest.raises(DataFormatError, match=f"rate of {10**9 // dt} Hz.*look like {unit}"):
        read_imu(write(tmp_path / "imu.csv", IMU_HEADER, imu_rows(dt=dt)))


def test_imu_stamps_too_far_apart_for_an_imu_are_refused(tmp_path):
    """Only stamps too close for an IMU were checked: picoseconds read as ns (a 200 Hz IMU at 0.2 Hz) passed, and a
    sequence built on them integrated 5 s per sample."""
    with pytest.raises(DataFormatError, match=r"rate of 0.2 Hz.*look like ps"):
        read_imu(write(tmp_path / "imu.csv", IMU_HEADER, imu_rows(dt=5_000_000_000)))


def test_imu_stamps_in_bursts_are_not_called_another_unit(tmp_path):
    """A driver that stamps each FIFO read: 10 samples 1 µs apart every 50 ms (200 Hz on average)."""
    t = [1_000_000_000 + (k // 10) * 50_000_000 + (k % 10) * 1_000 for k in range(200)]
    rows = [f"{s},0.01,0.02,0.03,0.1,0.2,9.8" for s in t]
    with pytest.raises(
        DataFormatError, match=r"in bursts: the median step is 1000 ns .* 2\d\d\.?\d* Hz on average"
    ) as e:
        read_imu(write(tmp_path / "imu.csv", IMU_HEADER, rows))
    assert "µs" not in str(e.value)


def test_a_header_without_its_hash_is_named(tmp_path):
    with pytest.raises(DataFormatError, match="A header line must start with '#'"):
        read_imu(write(tmp_path / "imu.csv", IMU_HEADER.lstrip("#"), imu_rows()))


def test_a_missing_sequence_says_whether_the_root_exists(tmp_path):
    (tmp_path / "root").mkdir()
    with pytest.raises(FileNotFoundError, match=r"root holds no sequence folder"):
        load_sequence(tmp_path / "root", "seq", cache_dir="")
    with pytest.raises(FileNotFoundError, match=r"nowhere does not exist \(relative paths start at "):
        load_sequence(tmp_path / "nowhere", "seq", cache_dir="")


def test_a_sequence_without_ground_truth_says_how_to_name_another_file(tmp_path):
    from gyrodenoise.data.readers import find_groundtruth_file

    mav0 = tmp_path / "walk_1" / "mav0"
    (mav0 / "vicon0").mkdir(parents=True)
    with pytest.raises(FileNotFoundError, match=r"\+dataset\.gt_files\.walk_1=FOLDER/data\.csv") as e:
        find_groundtruth_file(mav0)
    assert "gyrodenoise-correct for IMU-only recordings" in str(e.value)


def test_a_header_naming_fewer_columns_than_the_data_is_still_checked(tmp_path):
    """A header of t, p, q (w last) over data with velocity and biases after them was not compared: read as w first."""
    header = "#timestamp,p_x,p_y,p_z,q_x,q_y,q_z,q_w,v_x,v_y,v_z\n"  # 11 names, 17 columns below
    f = write(tmp_path / "gt.csv", header, gt_rows(extra=",0,0,0,0,0,0,0,0,0"))
    with pytest.raises(
        DataFormatError, match=r"gt.csv:1: column 5 is 'q_x' where quat w is expected.*w column before x"
    ):
        read_groundtruth(f)
    note = "# recorded by a logger, v1.2\n"  # a comment of few fields above the data is no header: read as before
    read_groundtruth(write(tmp_path / "ok.csv", GT_HEADER + note, gt_rows(extra=",0,0,0,0,0,0,0,0,0")))


def test_a_semicolon_file_and_exponent_stamps_get_their_own_advice(tmp_path):
    """A ';' file was blamed on a truncated line, and ns stamps in exponent form on a header without its '#'."""
    semi = write(tmp_path / "semi.csv", IMU_HEADER, [r.replace(",", ";") for r in imu_rows()])
    with pytest.raises(
        DataFormatError, match=r"semi.csv:2: .*separated by ';': the ASL format separates them by comma"
    ):
        read_imu(semi)
    expo = write(tmp_path / "expo.csv", IMU_HEADER, [f"{1e18 + k * 5e6:.6e}" + r[r.index(",") :] for k, r in
                                                      enumerate(imu_rows())])  # fmt: skip
    with pytest.raises(DataFormatError, match=r"expo.csv:2: .*'1.000000e\+18'.*write the nanoseconds as integers") as e:
        read_imu(expo)
    assert "header" not in str(e.value)


def test_a_sequence_folder_in_another_layout_is_not_called_missing(tmp_path):
    """rec_a/ holding imu.csv and gt.csv was 'not found', with 'did you mean rec_c?'."""
    from gyrodenoise.data.datamodule import ImuDataModule

    write(tmp_path / "rec_a" / "imu.csv", IMU_HEADER, imu_rows())
    write(tmp_path / "rec_c" / "mav0" / "imu0" / "data.csv", IMU_HEADER, imu_rows())
    said = r"rec_a exists but is not in the ASL layout: it has no mav0/ \(it holds imu.csv\); put the IMU in rec_a/mav0"
    with pytest.raises(FileNotFoundError, match=said):
        load_sequence(tmp_path, "rec_a", cache_dir="")
    dm = ImuDataModule(name="mine", root=str(tmp_path), train_seqs=["rec_a"], test_seqs=["rec_c"])
    with pytest.raises(FileNotFoundError, match=said) as e:
        dm.check_sequences()
    assert "did you mean" not in str(e.value)


def test_a_stamp_beyond_int64_names_the_line(tmp_path):
    """A stamp with extra digits (two lines run together) raised a bare 'Python int too large to convert to C long'
    that named neither the file nor the line."""
    rows = imu_rows()
    rows[5] = "99999999999999999999" + rows[5][rows[5].index(",") :]
    with pytest.raises(DataFormatError, match=r"imu.csv:7: column 1 \(timestamp\) is 99999999999999999999"):
        read_imu(write(tmp_path / "imu.csv", IMU_HEADER, rows))


def test_a_space_separated_file_is_not_called_truncated(tmp_path):
    """A ground truth in the TUM layout (fields separated by spaces) was told to 'fix or remove the truncated line'."""
    gt = write(tmp_path / "gt.txt", "# t tx ty tz qx qy qz qw\n", [r.replace(",", " ") for r in gt_rows()])
    with pytest.raises(
        DataFormatError, match=r"gt.txt:2: .*separated by spaces: the ASL format separates them by"
    ) as e:
        read_groundtruth(gt)
    assert "truncated" not in str(e.value)


def test_a_zero_quaternion_is_called_a_missing_pose_not_a_column_order(tmp_path):
    """A tracker that lost the body writes 0,0,0,0: it was told to check the column order and the file's units."""
    rows = gt_rows()
    for k in (10, 11, 12):
        rows[k] = rows[k].replace(",1,0,0,0", ",0,0,0,0")
    with pytest.raises(DataFormatError, match=r"gt.csv:12: quaternion .* is zero \(3 such lines\): no pose there") as e:
        read_groundtruth(write(tmp_path / "gt.csv", GT_HEADER, rows))
    assert "column order" not in str(e.value)
