"""gyrodenoise.data.imu_csv: the any-CSV reader of gyrodenoise-correct, on header and column variants."""

from __future__ import annotations

import numpy as np
import pytest

from gyrodenoise.data.imu_csv import read_imu_csv
from gyrodenoise.data.readers import read_csv_table

T0 = 1_600_000_000_000_000_000  # ns


def rows(n: int = 20, gyro: str = "10,20,30") -> list[str]:
    return [f"{T0 + k * 5_000_000},{gyro},0.5,0.7,9.8" for k in range(n)]


def write(path, lines: list[str]):
    path.write_text("".join(line + "\n" for line in lines))
    return path


@pytest.mark.parametrize("hashed", ["#", ""])
def test_a_note_above_the_header_does_not_take_its_place(tmp_path, hashed):
    """A comment line above the header (a logger's '# recorded by ...') was taken for the header, and its spaces for
    the delimiter: every line read as 1 column ('a recording without [the accelerometer] cannot be corrected'), or,
    with a comma in the note, the header's units (deg/s) were silently ignored."""
    header = f"{hashed}t [ns],gx [deg/s],gy [deg/s],gz [deg/s],ax,ay,az"
    for note in ("# recorded by logger X", "# recorded by logger X, version 2"):
        f = write(tmp_path / "note.csv", [note, header, *rows()])
        rec = read_imu_csv(f)
        assert rec.units["gyro"] == "deg/s" and rec.units_from_header == ["gyro"]
        np.testing.assert_allclose(rec.gyro[0], np.radians([10, 20, 30]))
        by_name = read_imu_csv(f, columns="t,gx,gy,gz,ax,ay,az")
        np.testing.assert_array_equal(by_name.gyro, rec.gyro)
        assert by_name.columns["wx"] == "column 2 (gx [deg/s])"


def test_a_note_below_the_header_does_not_take_its_place(tmp_path):
    f = write(tmp_path / "below.csv", ["#t,gx [deg/s],gy [deg/s],gz [deg/s],ax,ay,az", "# sensor: X", *rows()])
    assert read_imu_csv(f).units["gyro"] == "deg/s"


def test_both_readers_take_the_same_comment_line_for_the_header(tmp_path):
    """Two comment lines with the data's number of fields: `correct`'s reader took the first, the ASL readers the
    last (the nearest the data); both now take the last, so a file reads the same by either."""
    header = "#t [ns],gx [deg/s],gy [deg/s],gz [deg/s],ax,ay,az"
    f = write(tmp_path / "two.csv", ["# a,b,c,d,e,f,g", header, *rows()])
    with pytest.warns(UserWarning, match=r"two.csv: comment lines 1 and 2 have as many fields as the header; line 2"):
        assert read_imu_csv(f).units["gyro"] == "deg/s"  # the first line gave rad/s, the ASL default
    seen = []
    read_csv_table(f, 7, "IMU", check_header=lambda path, line, names: seen.append((line, names)))
    assert seen == [(2, [n.strip() for n in header.lstrip("#").split(",")])]


def test_column_number_zero_is_refused(tmp_path):
    """--columns 0,1,...: 0-based numbers; column 0 read the last column (Python's index -1)."""
    f = write(tmp_path / "x.csv", rows())
    with pytest.raises(ValueError, match=r"--columns '0,1,2,3,4,5,6': column numbers count from 1"):
        read_imu_csv(f, columns="0,1,2,3,4,5,6")


def test_a_first_line_ending_in_a_delimiter_is_data_not_a_header(tmp_path):
    """Lines ending in a comma (a logger printing 'a,b,c,') have an empty last field: the first line of a file without
    a header was taken for the header (it is 'not all numbers'), its sample silently dropped."""
    f = write(tmp_path / "trailing.csv", [r + "," for r in rows()])
    rec = read_imu_csv(f)
    assert len(rec) == 20 and rec.t_ns[0] == T0
    assert rec.columns["t"] == "column 1"
