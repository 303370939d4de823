"""Timestamps given to the streaming corrector: out of order, gaps and a wrong rate are caught before the state
changes; a clean stream gives the same outputs as without timestamps."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from _models import random_imu, random_model

from gyrodenoise.data.checks import SanityWarning
from gyrodenoise.models.ensemble import EnsembleCorrection
from gyrodenoise.stream_clock import StreamTimeError
from gyrodenoise.streaming import StreamingCorrector

PERIOD = 5_000_000  # ns, 200 Hz
ATOL = 2e-5  # rad/s: chunks of other lengths sum in another order


def stamps(n: int, start: int = 10**18, period: int = PERIOD) -> np.ndarray:
    return start + period * np.arange(n, dtype=np.int64)


@pytest.mark.parametrize("ensemble", [False, True])
def test_clean_stamps_change_nothing(ensemble):
    model = EnsembleCorrection([random_model(seed=1), random_model(seed=2)]).eval() if ensemble else random_model()
    imu, t = random_imu(700), stamps(700)
    plain, timed = StreamingCorrector(model), StreamingCorrector(model, rate_hz=200.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a stream at the model's rate gives no warning
        out = [timed.push(imu[k], t_ns=t[k]) for k in range(10)] + [timed.push_chunk(imu[10:], t_ns=t[10:])]
    ref = [plain.push(imu[k]) for k in range(10)] + [plain.push_chunk(imu[10:])]
    assert all(np.array_equal(a, b) for a, b in zip(out, ref, strict=True))


def test_a_gap_is_refused_and_leaves_the_state():
    model, imu = random_model(), random_imu(400)
    t = stamps(400)
    t[300:] += 40 * PERIOD  # 200 ms without samples
    ref = StreamingCorrector(model).push_chunk(imu[:300])
    sc = StreamingCorrector(model, rate_hz=200.0)
    sc.push_chunk(imu[:250], t_ns=t[:250])
    with pytest.raises(
        StreamTimeError, match=r"sample 51 of this call \(counting from 1\) comes 205\.000 ms after.*reset\(\)"
    ):
        sc.push_chunk(imu[250:310], t_ns=t[250:310])
    # nothing of the refused call went in: the stream goes on as if it had not been made
    assert np.abs(sc.push_chunk(imu[250:300], t_ns=t[250:300]) - ref[250:]).max() < ATOL
    with pytest.raises(StreamTimeError, match="ms after"):
        sc.push(imu[300], t_ns=t[300])
    sc.reset()  # what the message says to do: a new stream starts at the sample after the gap
    assert np.array_equal(sc.push(imu[300], t_ns=t[300]), StreamingCorrector(model).push(imu[300]))


def test_stamps_out_of_order_or_repeated_are_refused():
    sc = StreamingCorrector(random_model(), rate_hz=200.0)
    imu, t = random_imu(10), stamps(10)
    sc.push_chunk(imu[:5], t_ns=t[:5])
    with pytest.raises(StreamTimeError, match="this sample: timestamp .* is not after the previous"):
        sc.push(imu[5], t_ns=t[4])
    with pytest.raises(StreamTimeError, match=r"sample 3 of this call \(counting from 1\)") as refused:
        sc.push_chunk(imu[5:9], t_ns=t[[5, 6, 6, 7]])
    assert (refused.value.kind, refused.value.index) == ("order", 2)
    with pytest.raises(StreamTimeError, match="integer nanosecond"):
        sc.push(imu[5], t_ns=float(t[5]) * 1e-9)  # seconds as a float: refused, not misread
    with pytest.raises(ValueError, match="give t_ns with every push"):
        sc.push(imu[5])
    assert sc.push_chunk(imu[:0], t_ns=t[:0]).shape == (0, 3)  # an empty call is no sample and no stamp
    assert sc.n_pushed == 5 and sc.clock.last_ns == t[4]


@pytest.mark.parametrize("one_by_one", [False, True])
def test_a_stream_at_another_rate_warns_once(one_by_one):
    sc = StreamingCorrector(random_model(), rate_hz=200.0)
    imu, t = random_imu(1000), stamps(1000, period=5_500_000)  # 181.8 Hz: 10 % slow, within what the clock follows
    with pytest.warns(SanityWarning, match="runs at 181.8 Hz but the model was trained at 200 Hz"):
        if one_by_one:
            for k in range(500):
                sc.push(imu[k], t_ns=int(t[k]))
        else:
            sc.push_chunk(imu[:500], t_ns=t[:500])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        sc.push_chunk(imu[500:], t_ns=t[500:])


def test_a_stream_much_faster_than_the_model_is_refused_as_early():
    """A stream 25 % fast drifts ahead of the time base by a fifth of a period per sample: refused once its samples
    come more than 0.4 period before their expected time, with the rate its steps look like."""
    sc = StreamingCorrector(random_model(), rate_hz=200.0)
    with pytest.raises(StreamTimeError, match="look like a 250 Hz stream: the stream is faster") as refused:
        sc.push_chunk(random_imu(50), t_ns=stamps(50, period=4_000_000))
    assert refused.value.kind == "early" and 1 < refused.value.index < 10


def test_a_drivers_jitter_passes_and_twice_the_rate_does_not():
    """Stamps jittered by up to a quarter of a period (a late stamp, then an on-time one 'early' after it: steps of
    half a period, refused before the time base) are all taken, with the outputs of the unstamped stream; at twice
    the model's rate every other sample is refused."""
    model, imu = random_model(), random_imu(2000)
    rng = np.random.default_rng(0)
    t = stamps(2000) + rng.integers(-1_250_000, 1_250_001, 2000)
    sc = StreamingCorrector(model, rate_hz=200.0)
    out = np.array([sc.push(imu[k], t_ns=int(t[k])) for k in range(2000)])
    assert np.abs(out - StreamingCorrector(model).push_chunk(imu)).max() < ATOL
    sc = StreamingCorrector(model, rate_hz=200.0)
    t = stamps(40, period=PERIOD // 2)  # 400 Hz
    kinds = []
    for k in range(40):
        try:
            sc.push(imu[k], t_ns=int(t[k]))
            kinds.append("taken")
        except StreamTimeError as e:
            kinds.append(e.kind)
    assert kinds == ["taken", "early"] * 20


def test_without_a_rate_gaps_are_found_from_the_stream_itself():
    sc = StreamingCorrector(random_model())
    imu, t = random_imu(100), stamps(100)
    sc.push_chunk(imu[:50], t_ns=t[:50])
    with pytest.raises(StreamTimeError, match="more than 2.5 periods"):
        sc.push(imu[50], t_ns=t[50] + 10 * PERIOD)


def test_load_knows_the_training_rate():
    sc = StreamingCorrector.load("tumvi-denoiser")
    assert sc.clock.rate_hz is not None and 190 < sc.clock.rate_hz < 210


def test_stamps_in_another_unit_are_named():
    sc = StreamingCorrector(random_model(), rate_hz=200.0)
    imu, t = random_imu(20), stamps(20)
    with pytest.raises(StreamTimeError, match="integer nanoseconds .*micro- or milliseconds"):
        sc.push_chunk(imu, t_ns=t // 1000)  # microseconds: 5000 "ns" steps
    with pytest.raises(StreamTimeError, match=r"int\(round\(t_s \* 1e9\)\)"):
        sc.push_chunk(imu[:2], t_ns=np.array([1403715273, 1403715273]))  # integer seconds repeat
    assert sc.n_pushed == 0


@pytest.mark.parametrize("rate_hz", [200.003, 199.362])  # EuRoC's and TUM-VI's IMU rates
def test_two_missing_samples_are_a_gap_one_is_not(rate_hz):
    period = round(1e9 / rate_hz)
    sc = StreamingCorrector(random_model(), rate_hz=rate_hz)
    sc.push_chunk(random_imu(10), t_ns=stamps(10, period=period))
    last = int(sc.clock.last_ns)
    sc.push(random_imu(1)[0], t_ns=last + 2 * period)  # one sample missing: accepted
    with pytest.raises(StreamTimeError, match="more than 2.5 periods"):
        sc.push(random_imu(1)[0], t_ns=last + 5 * period)


def test_a_slow_stream_is_told_to_resample():
    sc = StreamingCorrector(random_model(), rate_hz=200.0)
    with pytest.raises(StreamTimeError, match="slower than the model's rate looks the same: resample it"):
        sc.push_chunk(random_imu(5), t_ns=stamps(5, period=20_000_000))  # 50 Hz


def test_a_model_without_memory_takes_a_gap():
    from gyrodenoise.models.build import build_model

    cal = build_model("calibrated").eval()
    sc = StreamingCorrector(cal, rate_hz=200.0)
    imu, t = random_imu(4), stamps(4)
    t[2:] += 100 * PERIOD
    assert np.array_equal(sc.push_chunk(imu, t_ns=t), StreamingCorrector(cal).push_chunk(imu))


def test_a_clock_gone_back_or_one_stamp_far_ahead_is_not_a_dead_end():
    """One stamp an hour ahead is taken as a new stream after a gap; every real sample after it is then 'before the
    last one taken'. The CLOCK_JUMP_SAMPLES-th in a row says the clock is elsewhere (kind 'clock'): reset and go on."""
    from gyrodenoise.stream_clock import CLOCK_JUMP_SAMPLES

    sc = StreamingCorrector(random_model(), rate_hz=200.0)
    imu, t = random_imu(100), stamps(100)
    sc.push_chunk(imu[:10], t_ns=t[:10])
    with pytest.raises(StreamTimeError) as refused:
        sc.push(imu[10], t_ns=int(t[10]) + 3600 * 10**9)
    assert refused.value.kind == "gap"
    sc.reset()
    sc.push(imu[10], t_ns=int(t[10]) + 3600 * 10**9)
    kinds = []
    for k in range(11, 11 + CLOCK_JUMP_SAMPLES):
        with pytest.raises(StreamTimeError) as refused:
            sc.push(imu[k], t_ns=int(t[k]))
        kinds.append(refused.value.kind)
    assert kinds == ["order"] * (CLOCK_JUMP_SAMPLES - 1) + ["clock"]
    assert "the stream's clock went back" in str(refused.value)
    sc.reset()
    sc.push(imu[k], t_ns=int(t[k]))
    sc.push(imu[k + 1], t_ns=int(t[k + 1]))  # the stream goes on at the real time


def test_an_accelerometer_in_g_is_said_once_after_the_first_samples():
    """`correct` refuses a file in g; a stream has no file: it warns once, after UNIT_PROBE samples, and goes on."""
    from gyrodenoise.streaming import UNIT_PROBE

    n = UNIT_PROBE + 50
    rng = np.random.default_rng(0)
    at_rest = np.hstack([rng.normal(0, 1e-3, (n, 3)), [0.0, 0.0, 1.0] + rng.normal(0, 1e-4, (n, 3))])  # acc in g
    sc = StreamingCorrector(random_model(), rate_hz=200.0)
    with pytest.warns(SanityWarning, match="norm is 1 at rest .* it looks like g; .* multiply it by 9.81"):
        sc.push_chunk(at_rest[:UNIT_PROBE], t_ns=stamps(UNIT_PROBE))
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # once per stream
        for k in range(UNIT_PROBE, n):
            sc.push(at_rest[k], t_ns=int(stamps(n)[k]))
        in_ms2 = at_rest * np.r_[1, 1, 1, 9.81, 9.81, 9.81]
        StreamingCorrector(random_model(), rate_hz=200.0).push_chunk(in_ms2, t_ns=stamps(len(in_ms2)))


def _robot_loop(sc, imu, t) -> list[str]:
    """docs/deployment.md's loop: a gap or a clock gone back restarts the stream, any other refusal drops the sample."""
    kinds = []
    for x, ti in zip(imu, t.tolist(), strict=True):
        try:
            sc.push(x, t_ns=ti)
            kinds.append("taken")
        except StreamTimeError as e:
            kinds.append(e.kind)
            if e.kind in ("gap", "clock"):
                sc.reset()
                sc.push(x, t_ns=ti)
    return kinds


def test_the_rate_is_the_samples_that_came_over_their_span():
    """Every other stamp 2.6 ms late at 200 Hz: all taken and no rate warning (steps of 7.6 ms left out of the average
    read as 400 Hz). At twice the model's rate the refused samples count too: the warning names 400 Hz."""
    model, imu = random_model(), random_imu(900)
    late = stamps(900) + np.where(np.arange(900) % 2, 2_600_000, 0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert set(_robot_loop(StreamingCorrector(model, rate_hz=200.0), imu, late)) == {"taken"}
    with pytest.warns(SanityWarning, match="runs at 400 Hz"):
        _robot_loop(StreamingCorrector(model, rate_hz=200.0), imu, stamps(900, period=PERIOD // 2))


def test_restarts_every_few_samples_warn_once():
    """A 100 Hz stream into a 200 Hz model: every other sample is a 'gap' the loop restarts at, no stream lasts the
    rate's 400 steps, and the outputs stay at start-up quality: said once."""
    model, imu = random_model(), random_imu(300)
    with pytest.warns(SanityWarning, match="the stream restarted 5 times within") as said:
        kinds = _robot_loop(StreamingCorrector(model, rate_hz=200.0), imu, stamps(300, period=3 * PERIOD))
    assert kinds.count("gap") > 100 and sum("restarted" in str(w.message) for w in said) == 1


def test_a_refused_chunk_names_its_first_refused_sample():
    """A sample after a gap, then one out of order: the gap is the first refusal, whatever is checked first."""
    sc = StreamingCorrector(random_model(), rate_hz=200.0)
    imu, t = random_imu(10), stamps(10)
    sc.push_chunk(imu[:3], t_ns=t[:3])
    with pytest.raises(StreamTimeError) as refused:
        sc.push_chunk(imu[3:6], t_ns=np.array([t[3] + 10**9, t[4], t[5]]))
    assert (refused.value.kind, refused.value.index) == ("gap", 0)


def test_a_file_and_a_stream_of_it_take_the_same_steps_as_gaps():
    from gyrodenoise.data.checks import FILE_GAP_FACTOR
    from gyrodenoise.stream_clock import STREAM_GAP_FACTOR

    assert FILE_GAP_FACTOR == STREAM_GAP_FACTOR


def test_an_empty_chunk_keeps_the_early_refusal_it_follows():
    """A review: an empty push_chunk cleared the flag that leaves the next step out of the rate's track (C, which has
    no empty push, kept it): Python and C would then disagree."""
    sc = StreamingCorrector(random_model(), rate_hz=200.0)
    sc.push_chunk(random_imu(5), t_ns=stamps(5))
    with pytest.raises(StreamTimeError):
        sc.push(random_imu(1)[0], t_ns=int(stamps(5)[-1]) + 1_000_000)
    assert sc.clock._early_since
    assert sc.push_chunk(random_imu(0), t_ns=np.zeros(0, dtype=np.int64)).shape == (0, 3)
    assert sc.clock._early_since
