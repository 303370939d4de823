"""The memo of repeated array computations (`gyrodenoise.sim.array_memo`) gives the numbers computed the first time,
as copies, keyed by content, within its byte bound; the low-pass, floor shape and shifted rate it serves are the
uncached numbers to the bit."""

from __future__ import annotations

import numpy as np

from gyrodenoise.sim import handheld_trajectory
from gyrodenoise.sim.array_memo import ArrayMemo, digest
from gyrodenoise.sim.effects import SensorBandwidth


def test_a_kept_result_is_a_copy_keyed_by_content():
    memo, calls = ArrayMemo(1 << 20), []

    def compute() -> np.ndarray:
        calls.append(1)
        return np.arange(6.0)

    x = np.ones((2, 3))
    first = memo.get(digest(x, 1.5), compute)
    first[0] = 99.0  # a caller's change does not reach the kept result
    again = memo.get(digest(x.copy(), 1.5), compute)  # another array with the same content
    assert calls == [1] and again[0] == 0.0 and (memo.hits, memo.misses) == (1, 1)
    # shape, dtype and the other parts are in the key
    for key in (digest(x.reshape(3, 2), 1.5), digest(x.astype(np.float32), 1.5), digest(x, 1.25), digest(x)):
        memo.get(key, compute)
    assert len(calls) == 5


def test_the_least_recently_used_result_is_dropped_beyond_the_bound():
    memo = ArrayMemo(2 * 80)  # room for two arrays of 10 float64
    for k in (b"a", b"b", b"a", b"c"):  # "a" read again before "c" comes in: "b" goes
        memo.get(k, lambda k=k: np.full(10, ord(k), dtype=np.float64))
    assert memo.misses == 3
    memo.get(b"a", lambda: np.zeros(10))
    memo.get(b"b", lambda: np.zeros(10))
    assert memo.misses == 4 and memo.get(b"c", lambda: np.zeros(10))[0] == 0.0  # "c" went to make room for "b"


def test_a_read_only_memo_hands_out_its_kept_array_and_holds_a_number_of_entries():
    """Keyed by identity (`time_only_rows`): the kept array itself, read-only, and the arrays of `keep` kept alive."""
    memo = ArrayMemo(max_entries=2, read_only=True)
    x = np.arange(3.0)
    first = memo.get(("rows", id(x)), lambda: x * 2, keep=(x,))
    assert memo.get(("rows", id(x)), lambda: x * 3) is first and not first.flags.writeable
    assert memo._kept[("rows", id(x))][0][0] is x
    memo.get("b", lambda: np.zeros(1))
    memo.get("c", lambda: np.zeros(1))  # a third entry: the first goes
    assert len(memo) == 2 and ("rows", id(x)) not in memo._kept


def test_memoised_filters_and_rates_equal_the_direct_computation():
    rng = np.random.default_rng(0)
    x = rng.standard_normal((2000, 3))
    direct = SensorBandwidth._filter_rate(x, 30.0, 200.0)
    for _ in range(2):  # computed, then kept
        assert np.array_equal(SensorBandwidth.filter_rate(x, 30.0, 200.0), direct)
    f = np.linspace(0.0, 100.0, 513)
    want = sum(np.sinc((f + k * 200.0) / 200.0) ** 2 / (1.0 + ((f + k * 200.0) / 30.0) ** 2) for k in range(-8, 9))
    for _ in range(2):
        assert np.allclose(SensorBandwidth.floor_shape(f, 30.0, 200.0), want, rtol=1e-14, atol=0)
    traj = handheld_trajectory(10.0, seed=1)
    t = np.linspace(1.0, 9.0, 300)
    direct = traj._rate_mean(t, 1 / 200, 4)
    for _ in range(2):
        assert np.array_equal(traj.rate_mean(t, 1 / 200), direct)
    other = handheld_trajectory(10.0, seed=2)  # another trajectory at the same times is not served the first's
    assert not np.array_equal(other.rate_mean(t, 1 / 200), direct)
