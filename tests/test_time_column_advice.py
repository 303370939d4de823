"""Advice for stamps a long log can have (from a scale audit): a clock that restarts once is not a file to sort, and
stamps too large for int64 ns read as ns are not in a finer unit than ns."""

from __future__ import annotations

import numpy as np
import pytest

from gyrodenoise.data.checks import SanityCheckError, run_checks
from gyrodenoise.data.imu_csv import read_imu_csv
from gyrodenoise.data.readers import DataFormatError


def _write(path, stamps):
    rows = [f"{t},0.01,0.02,0.03,0.1,0.2,9.8" for t in stamps]
    path.write_text("#t,wx,wy,wz,ax,ay,az\n" + "\n".join(rows) + "\n")
    return path


def test_a_clock_that_restarts_once_is_told_to_be_split_not_sorted(tmp_path):
    period = 5_000_000
    stamps = [10**15 + k * period for k in range(3000)] + [k * period for k in range(3000)]
    rec = read_imu_csv(_write(tmp_path / "reset.csv", stamps))
    said = r"reset.csv:3002.*restarted there, or a counter wrapped.*split the file"
    with pytest.raises(SanityCheckError, match=said):
        run_checks(rec, 200.0)


def test_stamps_out_of_order_in_many_places_are_told_to_be_sorted(tmp_path):
    stamps = np.arange(3000) * 5_000_000
    stamps[[100, 2000]] = stamps[[101, 2001]] + 1  # two local swaps
    rec = read_imu_csv(_write(tmp_path / "shuffled.csv", stamps.tolist()))
    with pytest.raises(SanityCheckError, match="Sort the file by time"):
        run_checks(rec, 200.0)


def test_stamps_beyond_int64_read_as_ns_are_not_told_to_be_read_as_ns(tmp_path):
    stamps = [17 * 10**18 + k * 5_000_000 for k in range(500)]  # 1.7e19: beyond int64
    with pytest.raises(DataFormatError, match=r"check the time column") as err:
        read_imu_csv(_write(tmp_path / "big.csv", stamps))
    assert "--time-unit ns" not in str(err.value)
