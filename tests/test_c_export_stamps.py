"""The C export's stamped step `gd_step_t` decides as StreamingCorrector.push(x, t_ns) does (`stream_clock`): the same
samples taken and refused, for the same reasons, boundaries included, and the same outputs within 1e-5 rad/s; after a
gap it restarts the stream where Python raises and its caller resets. Compiled with the host C compiler (skips
without one, as tests/test_c_export.py)."""

from __future__ import annotations

import subprocess
import warnings

import numpy as np
import pytest
import torch
from _models import random_imu, random_model

from gyrodenoise import c_clock, c_export
from gyrodenoise.data.checks import SanityWarning
from gyrodenoise.models.build import build_model
from gyrodenoise.models.ensemble import EnsembleCorrection
from gyrodenoise.stream_clock import StreamTimeError
from gyrodenoise.streaming import StreamingCorrector

ATOL = 1e-5  # rad/s, as tests/test_c_export.py
SMALL = {"channels": (8, 16, 12), "kernel_size": 3, "dilations": (1, 4, 9)}
CODE = {name: value for name, value, _ in c_clock.CODES}
SENTINEL = 1234.5  # the driver's outputs before a step: a refused step must leave them

# stdin: lines t,gx,gy,gz,ax,ay,az (t "-": gd_step, no stamp); stdout: code,wx,wy,wz per line
DRIVER = r"""
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "gyrodenoise_model.h"
static gd_state st;
int main(void)
{
    char line[512], t[32];
    float imu[6];
    while (fgets(line, sizeof line, stdin)) {
        float w[3] = {1234.5f, 1234.5f, 1234.5f}, sd[3];
        if (sscanf(line, "%31[^,],%g,%g,%g,%g,%g,%g", t, &imu[0], &imu[1], &imu[2], &imu[3], &imu[4], &imu[5]) != 7)
            return 2;
        const int code = strcmp(t, "-") == 0 ? gd_step(&st, imu, w, sd)
                                             : gd_step_t(&st, (int64_t)strtoll(t, NULL, 10), imu, w, sd);
        printf("%d,%.9g,%.9g,%.9g\n", code, (double)w[0], (double)w[1], (double)w[2]);
    }
    return 0;
}
"""


def stamped_sequence(lim: dict[str, int]) -> tuple[list[int | None], np.ndarray, list[str]]:
    """A 200 Hz stream with jitter, a repeated, a backwards and an early stamp, one missing sample, steps either side
    of the thresholds `lim`, a sample without a stamp, a NaN, gaps, then 410 steps at 185 Hz (the rate is compared
    after 400 steps): (stamps, samples, the codes a network at 200 Hz gives)."""
    rng = np.random.default_rng(3)
    stamps: list[int | None] = [1_403_636_579_000_000_000]
    expected, last = ["GD_OK"], stamps[0]

    def add(step: int, code: str = "GD_OK") -> None:
        nonlocal last
        stamps.append(last + step)
        expected.append(code)
        if code in ("GD_OK", "GD_RESTARTED", "GD_RATE_OFF"):
            last = last + step

    for step in 5_000_000 + rng.integers(-500_000, 500_000, 60):
        add(int(step))
    add(0, "GD_REFUSED_ORDER")  # repeated
    add(-3_000_000, "GD_REFUSED_ORDER")  # backwards
    add(2_000_000, "GD_REFUSED_EARLY")
    add(10_000_000)  # one sample missing: taken
    # each threshold right after a restart, where the time base is at the last sample taken (elsewhere it lags the
    # stamps by a fraction of their deviations: the thresholds hold against the expected time, not the last stamp)
    add(1_000_000_000, "GD_RESTARTED")
    add(lim["min_step"] - 1, "GD_REFUSED_EARLY")
    add(lim["min_step"])
    add(1_000_000_000, "GD_RESTARTED")
    add(lim["max_step"])
    add(1_000_000_000, "GD_RESTARTED")
    add(lim["max_step"] + 1, "GD_RESTARTED")
    add(5_000_000, "GD_REFUSED_UNSTAMPED")
    stamps[-1] = None  # no stamp on a stamped stream
    for _ in range(30):
        add(5_000_000)
    add(5_000_000, "GD_REFUSED_SAMPLE")
    nan_at = len(stamps) - 1
    add(5_000_000)
    add(1_000_000_000, "GD_RESTARTED")
    for _ in range(20):
        add(5_000_000)
    # one stamp an hour ahead (a corrupt stamp, taken as a new stream after a "gap"), then the real ones: refused as
    # late until CLOCK_JUMP_SAMPLES in a row say the clock is elsewhere, and the stream restarts there
    real = last + 5_000_000
    add(3_600 * 10**9, "GD_RESTARTED")
    jumps = c_clock.CLOCK_JUMP_SAMPLES
    for k in range(jumps + 5):
        stamps.append(real + k * 5_000_000)
        expected.append("GD_REFUSED_ORDER" if k < jumps - 1 else "GD_RESTARTED" if k == jumps - 1 else "GD_OK")
    last = stamps[-1]
    add(1_000_000_000, "GD_RESTARTED")
    for k in range(410):
        add(5_405_405, "GD_RATE_OFF" if k == 399 else "GD_OK")  # 185 Hz
    imu = random_imu(len(stamps), seed=9)
    imu[nan_at, 1] = np.nan
    return stamps, imu, expected


def python_decisions(model, rate_hz: float | None, stamps, imu) -> tuple[list[int], np.ndarray]:
    """StreamingCorrector.push on each sample: the code gd_step_t should return, and the output (NaN if refused)."""
    sc = StreamingCorrector(model, rate_hz=rate_hz)
    codes, out = [], np.full((len(imu), 3), np.nan)
    for n, (t, x) in enumerate(zip(stamps, imu.astype(np.float32), strict=True)):
        with warnings.catch_warnings(record=True) as said:
            warnings.simplefilter("always", SanityWarning)
            try:
                out[n] = sc.push(x, t_ns=t)
                code = "GD_OK"
            except StreamTimeError as e:
                if e.kind not in ("gap", "clock"):  # refused
                    code = {"order": "GD_REFUSED_ORDER", "early": "GD_REFUSED_EARLY"}[e.kind]
                else:  # a gap or a clock gone back: the caller resets and pushes it as the first of a new stream
                    sc.reset()
                    out[n] = sc.push(x, t_ns=t)
                    code = "GD_RESTARTED"
            except ValueError as e:
                code = "GD_REFUSED_UNSTAMPED" if "given timestamps" in str(e) else "GD_REFUSED_SAMPLE"
        # the rate's warning is GD_RATE_OFF; the warning about restarts every few samples has no C code
        if any(issubclass(w.category, SanityWarning) and "the stream runs at" in str(w.message) for w in said):
            code = "GD_RATE_OFF"
        codes.append(CODE[code])
    return codes, out


def c_decisions(
    model, meta: dict, stamps, imu, tmp_path, compiler, flags: tuple[str, ...] = ()
) -> tuple[list[int], np.ndarray]:
    out_dir = tmp_path / "c"
    c_export.export_c(model, out_dir, meta)
    (out_dir / "driver.c").write_text(DRIVER)
    exe = tmp_path / "driver"
    cmd = [*compiler.split(), "-O2", "-std=c99", "-Wall", "-Wextra", "-pedantic", "-Werror", "-Wdouble-promotion"]
    cmd += list(flags)
    done = subprocess.run(
        [*cmd, "-o", str(exe), str(out_dir / "driver.c"), str(out_dir / c_export.SOURCE), "-lm"],
        capture_output=True,
        text=True,
    )
    assert done.returncode == 0, done.stderr
    x = imu.astype(np.float32).tolist()
    lines = (
        ("-" if t is None else str(t)) + "," + ",".join(f"{v:.9g}" for v in r) for t, r in zip(stamps, x, strict=True)
    )
    done = subprocess.run([str(exe)], input="\n".join(lines) + "\n", capture_output=True, text=True, check=True)
    rows = np.array([ln.split(",") for ln in done.stdout.splitlines()], dtype=float)
    return rows[:, 0].astype(int).tolist(), rows[:, 1:]


def decided_alike(stamps: list[int], seed: int, tmp_path, compiler) -> list[int]:
    """A random network at 200 Hz on `stamps` in Python and in C: the same codes, the same outputs where taken."""
    model, imu = random_denoiser(), random_imu(len(stamps), seed=seed)
    codes, out = python_decisions(model, 200.0, stamps, imu)
    c_codes, c_out = c_decisions(model, {"name": "test", "rate_hz": 200.0}, stamps, imu, tmp_path, compiler)
    assert c_codes == codes
    taken = np.array(codes) >= 0
    assert np.abs(c_out[taken] - out[taken]).max() < ATOL
    return codes


def random_denoiser():
    model = random_model(seed=4, **SMALL)
    model.net[-1].weight.data *= 10  # corrections of ~1 rad/s: a sample fed twice or lost shows in the outputs
    return model


def calibrated():
    model = build_model("calibrated")
    model.bias.data[:] = torch.tensor([0.01, 0.02, -0.03])
    return model


@pytest.mark.parametrize(
    "build, rate_hz",
    [(random_denoiser, 200.0), (random_denoiser, None), (calibrated, 200.0)],
    ids=["network-200Hz", "network-rate-not-recorded", "calibrated-no-memory"],
)
def test_stamped_step_decides_as_the_streaming_corrector(build, rate_hz, tmp_path, compiler):
    model = build()
    stamps, imu, expected = stamped_sequence(c_clock.step_limits(200.0, True))
    codes, out = python_decisions(model, rate_hz, stamps, imu)
    meta = {"name": "test"} | ({"rate_hz": rate_hz} if rate_hz else {})
    c_codes, c_out = c_decisions(model, meta, stamps, imu, tmp_path, compiler)
    assert c_codes == codes
    taken = np.array(codes) >= 0
    assert np.abs(c_out[taken] - out[taken]).max() < ATOL
    assert (c_out[~taken] == SENTINEL).all()  # refused: nothing written
    seen = {name for name, value, _ in c_clock.CODES if value in codes}
    always = {"GD_OK", "GD_REFUSED_ORDER", "GD_REFUSED_SAMPLE", "GD_REFUSED_UNSTAMPED"}
    if build is calibrated:  # no memory: the order only (and its stamps restart where the clock went back)
        assert seen == always | {"GD_RESTARTED"}
    elif rate_hz:
        assert codes == [CODE[c] for c in expected]
    else:  # the period learnt from the stream: gaps only, no rate
        assert seen == always | {"GD_RESTARTED"}


def test_a_jittery_stream_is_judged_alike_against_the_time_base(tmp_path, compiler):
    """Stamps jittered by up to 0.38 period (some come more than 0.4 period before their expected time: refused), then
    a stream 3 % slow and one 7 % fast: the time base moves identically in C (integer ns, C99 division) and Python."""
    rng = np.random.default_rng(5)
    jitter = 5_000_000 * np.arange(1500) + rng.integers(-1_900_000, 1_900_001, 1500)
    slow = jitter[-1] + 5_150_000 * np.arange(1, 501)
    fast = slow[-1] + 4_650_000 * np.arange(1, 501)
    stamps = (1_403_636_579_000_000_000 + np.concatenate([jitter, slow, fast])).tolist()
    codes = decided_alike(stamps, 2, tmp_path, compiler)
    assert 0 < codes.count(CODE["GD_REFUSED_EARLY"]) < 0.05 * len(codes)  # the jitter's rare outliers, the fast part


def test_thresholds_are_the_stream_clocks():
    """The integer thresholds written into the C code are where StreamClock's float tests change their answer."""
    from gyrodenoise.stream_clock import StreamClock

    for rate in (200.0, 200.00263, 100.0, 333.3):
        lim = c_clock.step_limits(rate, True)
        for step, refused in ((lim["min_step"] - 1, True), (lim["min_step"], False)):
            clock = StreamClock(rate)
            clock.commit(clock.check(0, 1))
            if refused:
                with pytest.raises(StreamTimeError, match="faster"):
                    clock.check(step, 1)
            else:
                clock.check(step, 1)
        for step, gap in ((lim["max_step"], False), (lim["max_step"] + 1, True)):
            clock = StreamClock(rate)
            clock.commit(clock.check(0, 1))
            if gap:
                with pytest.raises(StreamTimeError, match="periods"):
                    clock.check(step, 1)
            else:
                clock.check(step, 1)


def test_example_reads_stamps_drops_refused_samples_and_restarts_after_a_gap(tmp_path, compiler):
    """example_main.c calls gd_step_t with each line's t: a repeated stamp is dropped (no output line, said on stderr,
    exit 1), a gap restarts the stream (said), t in seconds is refused naming the fix; --unstamped ignores t."""
    model = random_denoiser()
    c_export.export_c(model, tmp_path / "c", {"name": "test", "rate_hz": 200.0})
    exe = c_export.compile_example(tmp_path / "c", tmp_path / "gd", compiler, werror=True)
    imu = random_imu(40, seed=2)
    t = 1_000_000_000 + 5_000_000 * np.arange(40)
    t[20:] += 2_000_000_000  # a 2 s gap before sample 20
    gyro, _ = c_export.run_example(exe, imu, t)
    sc = StreamingCorrector(model, rate_hz=200.0)
    ref = [sc.push(x) for x in imu[:20].astype(np.float32)]
    sc.reset()
    ref += [sc.push(x) for x in imu[20:].astype(np.float32)]
    assert np.abs(gyro - np.array(ref)).max() < ATOL

    def run(text: str, *args: str) -> subprocess.CompletedProcess:
        return subprocess.run([str(exe), *args], input=text, capture_output=True, text=True)

    text = c_export.example_input(imu, t)
    done = run(text)
    restarted = "line 22 (sample 21, t=3100000000): a gap before it, or the clock went back: the stream restarted"
    assert done.returncode == 0 and restarted in done.stderr
    repeated = text.replace("\n1010000000,", "\n1005000000,")  # sample 3 stamped as sample 2
    done = run(repeated)
    assert (
        done.returncode == 1 and "line 4 (sample 3, t=1005000000): its stamp is not after the previous" in done.stderr
    )
    assert len(done.stdout.splitlines()) == 1 + 39 and "1 of 40 samples refused" in done.stderr
    seconds = "t,gx,gy,gz,ax,ay,az\n1403636579.758555,0,0,0,0,0,9.8\n"
    done = run(seconds)
    assert done.returncode == 1 and "line 2: t=1403636579.758555 is not integer nanoseconds" in done.stderr
    assert "--unstamped" in done.stderr
    done = run(seconds, "--unstamped")
    assert done.returncode == 0 and done.stdout.splitlines()[1].startswith("1403636579.758555,")
    assert run("", "--bad").returncode == 2
    # nothing dropped silently: a line without t, a line of 8 columns, a line longer than the buffer end the run
    done = run("t,gx,gy,gz,ax,ay,az\n,0,0,0,0,0,9.8\n")
    assert done.returncode == 1 and "line 2: t= is not integer nanoseconds" in done.stderr
    done = run("# a comment\r\n\r\n1000000000,0,0,0,0,0,9.8,17\r\n")
    assert done.returncode == 1 and "line 3: more than 7 columns" in done.stderr
    done = run("1000000000," + "0" * 2000 + ",0,0,0,0,9.8\n")
    assert done.returncode == 1 and "line 1: longer than" in done.stderr
    assert run("1000000000,0,0,0,0,0,9.8\r\n").returncode == 0  # CRLF line ends
    # a fresh-user audit: a header putting the accelerometer first read g as rad/s without a word; a short line ended
    # the run saying nothing of the lines it did not read
    done = run("time_ns,acc_x,acc_y,acc_z,gyro_x,gyro_y,gyro_z\n1000000000,0,0,9.8,0,0,0\n")
    assert done.returncode == 1 and not done.stdout.strip().splitlines()[1:]
    assert "line 1: the header names column 2 'acc_x' where gyro x is read" in done.stderr
    done = run(text.replace("\n1010000000,", "\n1010000000\n", 1))  # sample 3 cut short
    assert done.returncode == 1 and len(done.stdout.splitlines()) == 1 + 2
    assert "line 4: expected t,gx,gy,gz,ax,ay,az; stopped there: the lines after it were not read (the 2 samples" in (
        done.stderr
    )
    assert (
        run("#timestamp [ns],w_x [rad s^-1],w_y,w_z,a_x [m s^-2],a_y,a_z\n1000000000,0,0,0,0,0,9.8\n").returncode == 0
    )


def test_example_output_header_is_a_comment_with_units(tmp_path, compiler):
    """The header line starts with '#', as the project's other CSV outputs (`correct`'s imu_corrected.csv); it had
    none. The lines after it are the samples."""
    for members in (1, 2):
        model = random_denoiser() if members == 1 else EnsembleCorrection([random_denoiser(), random_denoiser()])
        c_export.export_c(model, tmp_path / f"c{members}", {"name": "test", "rate_hz": 200.0})
        exe = c_export.compile_example(tmp_path / f"c{members}", tmp_path / f"gd{members}", compiler, werror=True)
        imu = random_imu(5, seed=1)
        done = subprocess.run(
            [str(exe)], input=c_export.example_input(imu, 1_000_000_000 + 5_000_000 * np.arange(5)),
            capture_output=True, text=True, check=True,
        )  # fmt: skip
        header, *rows = done.stdout.splitlines()
        std = ",w_std_x [rad s^-1],w_std_y [rad s^-1],w_std_z [rad s^-1]" if members == 2 else ""
        assert header == "#t,wx [rad s^-1],wy [rad s^-1],wz [rad s^-1]" + std
        assert len(rows) == 5 and all(not r.startswith("#") for r in rows)
        gyro, spread = c_export.run_example(exe, imu)  # the project's reader skips it
        assert gyro.shape == (5, 3) and (spread is None) == (members == 1)


def _turning(n: int, p99_rad_s: float, seed: int = 0) -> np.ndarray:
    """n IMU samples whose gyro norms have the 99th percentile `p99_rad_s` (numpy's), acc about gravity."""
    rng = np.random.default_rng(seed)
    norms = rng.uniform(0.1, 0.9, n) * p99_rad_s
    norms[: max(n // 50, 2)] = p99_rad_s * 1.2  # 2 % above: the 99th percentile in their midst
    norms *= p99_rad_s / np.percentile(norms, 99)
    axes = rng.normal(size=(n, 3))
    gyro = axes / np.linalg.norm(axes, axis=1, keepdims=True) * norms[:, None]
    return np.concatenate([gyro, rng.normal(0, 0.1, (n, 3)) + [0, 0, 9.81]], axis=1)


def test_example_stops_a_gyro_in_deg_s_as_the_streaming_corrector_warns(tmp_path, compiler):
    """The C example read a gyro in deg/s as rad/s without a word. It now applies the streaming corrector's range
    rule (99th-percentile |gyro| over the first UNIT_PROBE samples above GYRO_P99_MAX rad/s) and stops at the line of
    the last of them; a stream of fewer samples, or below the threshold, runs as before, and Python agrees."""
    from gyrodenoise.data.checks import GYRO_P99_MAX
    from gyrodenoise.streaming import UNIT_PROBE

    model = random_denoiser()
    c_export.export_c(model, tmp_path / "c", {"name": "test", "rate_hz": 200.0})
    exe = c_export.compile_example(tmp_path / "c", tmp_path / "gd", compiler, werror=True)
    n = UNIT_PROBE + 100
    t = 1_000_000_000 + 5_000_000 * np.arange(n)

    def run(imu: np.ndarray, *args: str) -> subprocess.CompletedProcess:
        text = c_export.example_input(imu, None if args else t[: len(imu)])
        return subprocess.run([str(exe), *args], input=text, capture_output=True, text=True)

    def python_warns(imu: np.ndarray) -> bool:
        sc = StreamingCorrector(model)
        with warnings.catch_warnings(record=True) as seen:
            warnings.simplefilter("always")
            for x in imu:
                sc.push(x)
        return any("looks like deg/s" in str(w.message) for w in seen if issubclass(w.category, SanityWarning))

    in_deg = _turning(n, GYRO_P99_MAX * 1.05)
    for args in ((), ("--unstamped",)):
        done = run(in_deg, *args)
        assert done.returncode == 1, done.stderr
        line = UNIT_PROBE + 1  # the header is line 1
        assert f"line {line} (sample {UNIT_PROBE}, t=" in done.stderr
        assert f"99th-percentile norm over the first {UNIT_PROBE} samples is" in done.stderr
        assert "it looks like deg/s" in done.stderr and "multiply the gyro by pi/180" in done.stderr
        assert len(done.stdout.splitlines()) == 1 + UNIT_PROBE - 1  # stopped there: nothing after it
    assert python_warns(in_deg)

    in_rad = _turning(n, GYRO_P99_MAX * 0.95)
    done = run(in_rad)
    assert done.returncode == 0 and "deg/s" not in done.stderr and len(done.stdout.splitlines()) == 1 + n
    assert not python_warns(in_rad)
    short = in_deg[: UNIT_PROBE - 1]  # too few samples to judge: neither says anything
    done = run(short)
    assert done.returncode == 0 and "deg/s" not in done.stderr
    assert not python_warns(short)


INT64_MAX, INT64_MIN = 2**63 - 1, -(2**63)


@pytest.mark.parametrize("build", [random_denoiser, calibrated], ids=["network", "calibrated"])
def test_stamps_at_the_ends_of_int64_decide_alike_without_overflow(build, tmp_path, compiler):
    """An audit under UBSan: the time base's sums overflowed int64 near its ends (undefined behaviour; a build
    without the sanitizer refused as early what Python took as a gap). Built with -fsanitize=undefined, which stops
    at the first overflow, the C decides as Python on stamps at and across the ends of int64."""
    stamps = [INT64_MAX - 10, INT64_MAX, INT64_MIN, INT64_MIN + 5_000_000, INT64_MAX, 0, 5_000_000, 2**62, 2**62 + 5]
    stamps += [-(2**62), 10_000_000, 15_000_000]
    stamps += [INT64_MAX - 4_000_000, INT64_MAX]  # taken 0.8 of a period after the last: the base lies past INT64_MAX
    imu = random_imu(len(stamps), seed=3)
    model = build()
    codes, out = python_decisions(model, 200.0, stamps, imu)
    ub = ("-fsanitize=undefined", "-fno-sanitize-recover=all")
    c_codes, c_out = c_decisions(model, {"name": "t", "rate_hz": 200.0}, stamps, imu, tmp_path, compiler, ub)
    assert c_codes == codes
    taken = np.array(codes) >= 0
    assert np.abs(c_out[taken] - out[taken]).max() < ATOL


def test_a_nan_is_refused_by_a_fast_math_build(tmp_path, compiler):
    """-ffast-math lets the compiler fold isfinite() to 1: a NaN was taken (GD_OK) and spoilt every later output
    until a reset. The check reads the float's bits."""
    stamps = [k * 5_000_000 for k in range(6)]
    imu = random_imu(len(stamps), seed=4)
    imu[2, 0] = np.nan
    imu[4, 5] = np.inf
    model = random_denoiser()
    codes, _ = python_decisions(model, 200.0, stamps, imu)
    c_codes, _ = c_decisions(model, {"name": "t", "rate_hz": 200.0}, stamps, imu, tmp_path, compiler, ("-ffast-math",))
    assert c_codes == codes and codes[2] == codes[4] == CODE["GD_REFUSED_SAMPLE"]


def test_the_time_base_follows_the_streams_rate_and_steps_over_a_missing_sample(tmp_path, compiler):
    """An audit: the base's step was the model's period, so a stream 3-4 % fast with +-1.5 ms of jitter had 4-5 % of
    its samples refused as early, and two single missing samples a few samples apart restarted the stream. Now the
    step is the stream's mean interval and a sample about a period late steps over one missing: C decides alike."""
    rng = np.random.default_rng(7)
    n = 3000
    t = np.arange(n) * 5_000_000 / 1.04 + rng.uniform(-1_500_000, 1_500_000, n)  # 4 % fast, +-0.3 period
    drops = np.sort(rng.choice(np.arange(100, n - 1, 3), 60, replace=False))  # single samples, some 3 apart
    stamps = (1_403_636_579_000_000_000 + np.delete(t, drops).astype(np.int64)).tolist()
    codes = decided_alike(stamps, 3, tmp_path, compiler)
    assert codes.count(CODE["GD_RESTARTED"]) == 0 and codes.count(CODE["GD_REFUSED_EARLY"]) < 0.005 * len(codes)


@pytest.mark.parametrize("slow", [0.2, 0.4, 0.5])
def test_a_stream_much_slower_than_the_model_is_still_refused_as_gaps(slow, tmp_path, compiler):
    """A review: stepping over one missing sample, as often as it came, took a stream 20-50 % slow (100 Hz into a
    200 Hz model) without a gap, only a rate warning. A step-over needs a step of about two periods, and at most one in
    MISSED_SHARE samples: C decides alike."""
    stamps = (1_000_000_000 + np.round(np.arange(600) * 5e6 / (1 - slow))).astype(np.int64).tolist()
    codes = decided_alike(stamps, 4, tmp_path, compiler)
    assert codes.count(CODE["GD_RESTARTED"]) > 0.04 * len(codes)  # 4.7 % at 20 % slow before
