"""The C export's stamped step, `gd_step_t`: the timestamp rules of `gyrodenoise.stream_clock`, in C.

    int gd_step_t(gd_state *s, int64_t t_ns, const float imu[6], float gyro_out[3], float *std_out);

StreamingCorrector.push(x, t_ns) refuses a stamp that is not after the previous one, one that comes more than
1 - STREAM_FAST_FACTOR periods before its expected time on the stream's time base, and one after a gap (more than
STREAM_GAP_FACTOR - 1 periods after it), all with the state unchanged; it warns once when the first RATE_WINDOW
intervals of a stream (steps taken, samples refused as early) average a rate more than RATE_TOL off the model's.
`gd_step_t` makes the same decisions, as return codes (`CODES`): refused (< 0, state unchanged, nothing written), or
taken (>= 0, outputs written). After a gap, or CLOCK_JUMP_SAMPLES stamps in a row before the last one taken, it does
what the Python caller does next (reset(), then push the sample as the first of a new stream) and says so
(GD_RESTARTED): an onboard loop cannot stop there.

The thresholds are computed here in float64 as StreamClock computes them, and written as integer nanoseconds, so that
the C decisions (integer arithmetic, no float and no double on the target) are Python's, boundaries included. A model
without memory (a calibrated one) checks the order only, as StreamClock(gaps=False); a model whose rate is not
recorded learns its period from the stream's mean step (gaps only), as StreamClock(rate_hz=None).
"""

from __future__ import annotations

import math

from gyrodenoise.data.checks import RATE_TOL
from gyrodenoise.stream_clock import (
    CLOCK_JUMP_SAMPLES,
    MISSED_SHARE,
    RATE_TRACK_MIN,
    RATE_WINDOW,
    STREAM_FAST_FACTOR,
    STREAM_GAP_FACTOR,
    TIME_BASE_GAIN,
    rate_sum_bounds,
)

# name, value, meaning (the header's #defines)
CODES = (
    ("GD_OK", 0, "taken"),
    (
        "GD_RESTARTED",
        1,
        "gd_step_t: taken after a gap (or a missing sample beyond 1 in GD_MISSED_SHARE), or after "
        "GD_CLOCK_JUMP_SAMPLES stamps in a row before the last one taken (the clock went back): a new stream",
    ),
    ("GD_RATE_OFF", 2, "gd_step_t: taken; the stream's rate is over GD_RATE_TOL off GD_RATE_HZ"),
    ("GD_REFUSED_SAMPLE", -1, "a NaN/inf, or a value beyond GD_GYRO_ABS_MAX / GD_ACC_ABS_MAX"),
    ("GD_REFUSED_ORDER", -2, "gd_step_t: the stamp is not after the previous one"),
    (
        "GD_REFUSED_EARLY",
        -3,
        "gd_step_t: under GD_MIN_STEP_NS after where the time base puts the last sample taken (without a rate: after "
        "the last stamp)",
    ),
    ("GD_REFUSED_UNSTAMPED", -4, "gd_step on a stream that gd_step_t stamped"),
)
INT64_MAX = 2**63 - 1


def step_limits(rate_hz: float, memory: bool) -> dict[str, int]:
    """The stamped step's thresholds in ns, as StreamClock decides: min_step (shorter: refused), max_step (longer:
    a gap; 0: GAP_FACTOR x the stream's mean step; -1: none), and the sum of the first RATE_WINDOW steps that does
    not warn, [rate_sum_min, rate_sum_max]."""
    free = {"min_step": 1, "rate_sum_min": 0, "rate_sum_max": INT64_MAX, "period": 0, "step_max_off": 0}
    if not memory:  # StreamClock(None, gaps=False): the order only
        return {**free, "max_step": -1}
    if not rate_hz:  # StreamClock(None): the period learnt from the stream (gaps only)
        return {**free, "max_step": 0}
    period = 1e9 / rate_hz  # StreamClock.period_ns
    lo, hi = rate_sum_bounds(rate_hz)
    return {
        "min_step": math.ceil(STREAM_FAST_FACTOR * period),  # refused: a step < FAST x period
        "max_step": math.floor(STREAM_GAP_FACTOR * period),  # a gap: a step > GAP x period
        "rate_sum_min": lo,
        "rate_sum_max": hi,
        "period": round(period),  # the time base's step (StreamClock._base)
        "step_max_off": math.floor(RATE_TOL * round(period)),  # StreamClock._step_max_off
    }


def _gap_fraction() -> tuple[int, int]:
    """STREAM_GAP_FACTOR as numerator / denominator (2.5 = 5 / 2), for an exact integer test in C."""
    return STREAM_GAP_FACTOR.as_integer_ratio()


def header_defines(rate_hz: float, memory: bool) -> str:
    """The #defines of the stamp rules and of the return codes."""
    lim = step_limits(rate_hz, memory)
    if not memory:
        min_doc, max_doc = "1: any increasing stamp", "-1: none (a model without memory)"
    elif not rate_hz:
        min_doc, max_doc = "1: any increasing stamp (no rate)", "0: GAP_FACTOR x the stream's mean step (no rate)"
    else:
        min_doc = "ceil(FAST_FACTOR x period): a sample earlier after the time base's last one is refused"
        max_doc = "floor(GAP_FACTOR x period): a sample later after the time base's last one restarts"
    rows = [
        ("GD_STAMP_FAST_FACTOR", f"{STREAM_FAST_FACTOR!r}f", "GD_MIN_STEP_NS in periods"),
        ("GD_STAMP_GAP_FACTOR", f"{STREAM_GAP_FACTOR!r}f", "GD_MAX_STEP_NS in periods"),
        ("GD_MIN_STEP_NS", f"INT64_C({lim['min_step']})", min_doc),
        ("GD_MAX_STEP_NS", f"INT64_C({lim['max_step']})", max_doc),
        ("GD_PERIOD_NS", f"INT64_C({lim['period']})", "the time base's step (0: none, the steps alone decide)"),
        ("GD_TIME_BASE_GAIN", str(TIME_BASE_GAIN), "the time base moves by 1/this of a sample's deviation"),
        ("GD_RATE_TRACK_MIN", str(RATE_TRACK_MIN), "intervals taken before its step is their mean, not the period"),
        ("GD_STEP_MAX_OFF_NS", f"INT64_C({lim['step_max_off']})", "its step within this of GD_PERIOD_NS"),
        ("GD_MISSED_SHARE", str(MISSED_SHARE), "a missing sample stepped over more than 1 in this many: a gap"),
        ("GD_CLOCK_JUMP_SAMPLES", str(CLOCK_JUMP_SAMPLES), "this many stamps in a row before the last: restart"),
        ("GD_RATE_WINDOW", str(RATE_WINDOW), "steps (and early refusals) averaged, once per stream, for the rate"),
        ("GD_RATE_TOL", f"{RATE_TOL!r}f", "relative rate difference that gives GD_RATE_OFF"),
    ]
    stamps = "\n".join(f"#define {n:<20} {v:<18} /* {doc} */" for n, v, doc in rows)
    codes = "\n".join(f"#define {n:<20} {f'({v})' if v < 0 else v:<4} /* {doc} */" for n, v, doc in CODES)
    return (
        "/* The stamp rules of gd_step_t, gyrodenoise.stream_clock's (period: 1e9 / the model's rate, in ns) */\n"
        f"{stamps}\n\n/* Return codes: >= 0 the sample was taken (outputs written); < 0 it was refused (the state is\n"
        f"   unchanged, nothing is written: drop the sample) */\n{codes}"
    )


STATE_FIELDS = """\
    int stamped;                                          /* gd_step_t has stamped this stream */
    int64_t last_ns;                                      /* the stamp of its last sample */
    int64_t lag_ns;                                       /* its last stamp less where the time base puts it */
    uint64_t track_ns, track_n;                           /* its taken steps' sum and intervals (base_step) */
    int early_since;                                      /* a GD_REFUSED_EARLY since its last sample taken */
    uint64_t n_missed;                                    /* its samples stepped over as missing */
    int late_in_a_row;                                    /* samples refused in a row as GD_REFUSED_ORDER */
    uint64_t steps_ns, n_steps;                           /* the sum and number of its steps */
    uint64_t n_early;                                     /* its samples refused as GD_REFUSED_EARLY */
    int rate_checked;                                     /* its rate was compared */"""

DECLARATION = """\
/* gd_step with the sample's timestamp t_ns [integer nanoseconds, any epoch, the whole int64 range]: the checks of
   gyrodenoise's StreamingCorrector.push(imu, t_ns) (stream_clock), as return codes (the GD_* above):
   - GD_REFUSED_SAMPLE, GD_REFUSED_ORDER, GD_REFUSED_EARLY: refused, nothing is written (drop the
     sample; the next one is compared with the last taken), the state is unchanged but for two counts: of
     GD_REFUSED_ORDER in a row (GD_CLOCK_JUMP_SAMPLES of them restart) and of GD_REFUSED_EARLY (the rate's average
     counts them; the next step taken is left out of the time base's mean interval);
   With the model's rate (GD_PERIOD_NS > 0) a sample is judged against its expected time: the stream's time base
   advances one step per sample taken (GD_PERIOD_NS; after GD_RATE_TRACK_MIN intervals the stream's mean interval,
   within GD_STEP_MAX_OFF_NS of it) and follows the stamps by 1/GD_TIME_BASE_GAIN of their deviation, so a driver's
   jitter passes; a sample a step less the early tolerance late or more, two steps after the last one taken, is one
   missing sample, stepped over (beyond one in GD_MISSED_SHARE samples taken: a gap, GD_RESTARTED);
   - GD_RESTARTED: after a gap, the sample started a new stream (Python raises there; its caller resets and pushes);
   - GD_RATE_OFF: taken, and the stream's rate is off the model's (Python warns).
   Use one of gd_step / gd_step_t per stream (gd_step on a stamped stream: GD_REFUSED_UNSTAMPED). Each gd_state is
   one stream: the functions keep no other state (no globals), so streams on other threads need states of their own
   and no lock. */
int gd_step_t(gd_state *s, int64_t t_ns, const float imu[6], float gyro_out[3], float *std_out);"""


def source_code(rate_hz: float, memory: bool) -> str:
    """gd_reset, gd_step and gd_step_t (they call `step`, the unchecked step, and `sample_ok`)."""
    lim = step_limits(rate_hz, memory)
    num, den = _gap_fraction()
    return f"""\
/* the first GD_RATE_WINDOW steps of a stream sum to [rate_sum_min, rate_sum_max] ns unless its rate is more than
   GD_RATE_TOL off GD_RATE_HZ (StreamClock's test, as integers) */
static const uint64_t rate_sum_min = UINT64_C({lim["rate_sum_min"]}), rate_sum_max = UINT64_C({lim["rate_sum_max"]});

void gd_reset(gd_state *s)
{{
    s->started = 0;
    memset(s->newest, 0, sizeof s->newest); /* a state never zeroed (on the stack) holds any index here */
    s->stamped = 0;
    s->last_ns = s->lag_ns = 0;
    s->track_ns = s->track_n = 0;
    s->early_since = 0;
    s->n_missed = 0;
    s->late_in_a_row = 0;
    s->steps_ns = s->n_steps = s->n_early = 0;
    s->rate_checked = 0;
}}

int gd_step(gd_state *s, const float imu[6], float gyro_out[3], float *std_out)
{{
    if (!sample_ok(imu)) return GD_REFUSED_SAMPLE;
    if (s->stamped) return GD_REFUSED_UNSTAMPED;
    step(s, imu, gyro_out, std_out);
    return GD_OK;
}}

/* a step (> 0 ns) longer than GD_MAX_STEP_NS, or than {num}/{den} (GD_STAMP_GAP_FACTOR) of the stream's mean step */
static int is_gap(const gd_state *s, uint64_t step_ns)
{{
    if (GD_MAX_STEP_NS > 0) return step_ns > (uint64_t)GD_MAX_STEP_NS;
    if (GD_MAX_STEP_NS < 0 || s->n_steps == 0) return 0;
    return step_ns > (UINT64_C({num}) * s->steps_ns) / (UINT64_C({den}) * s->n_steps);
}}

/* a taken sample's stamp less where the time base puts it, dev ns after its expected time: the base moves by
   dev / GD_TIME_BASE_GAIN (C99's division truncates toward zero, as StreamClock's _toward_zero). Kept as this small
   lag, not as the base itself, which near the ends of int64 may lie beyond them */
static int64_t lag_after(int64_t dev)
{{
    return dev - dev / GD_TIME_BASE_GAIN;
}}

/* the time base's step: GD_PERIOD_NS, or the taken samples' mean interval once GD_RATE_TRACK_MIN were taken, within
   GD_STEP_MAX_OFF_NS of it (StreamClock.base_step). The mean of a stream's steps: a loop on the deviations would see
   those of one sign only where samples are refused as early, and drift off */
static int64_t base_step(const gd_state *s)
{{
    int64_t off; /* a taken step is at most a few periods: the mean fits int64 */
    if (s->track_n < GD_RATE_TRACK_MIN) return GD_PERIOD_NS;
    off = (int64_t)(s->track_ns / s->track_n) - GD_PERIOD_NS;
    off = off > GD_STEP_MAX_OFF_NS ? GD_STEP_MAX_OFF_NS : off < -GD_STEP_MAX_OFF_NS ? -GD_STEP_MAX_OFF_NS : off;
    return GD_PERIOD_NS + off;
}}

/* the sample's deviation from its expected time, without overflow for any int64 stamps: from the step since the
   last stamp (exact as unsigned: t_ns > last_ns), the base's small lag behind that stamp and its step; a step over
   2^62 ns is a gap whatever the lag (*gap set, no deviation) */
static int64_t deviation(const gd_state *s, uint64_t step_ns, int64_t bstep, int *gap)
{{
    *gap = step_ns > (UINT64_C(1) << 62);
    return *gap ? 0 : (int64_t)step_ns + s->lag_ns - bstep;
}}

int gd_step_t(gd_state *s, int64_t t_ns, const float imu[6], float gyro_out[3], float *std_out)
{{
    int code = GD_OK;
    uint64_t step_ns = 0;
    int64_t dev = 0, bstep = 0;
    int missed = 0;
    if (!sample_ok(imu)) return GD_REFUSED_SAMPLE;
    if (s->stamped) {{
        if (t_ns <= s->last_ns && ++s->late_in_a_row < GD_CLOCK_JUMP_SAMPLES) return GD_REFUSED_ORDER;
        if (t_ns <= s->last_ns) {{ /* the clock went back, or the last stamp taken was wrong: a new stream */
            gd_reset(s);
            code = GD_RESTARTED;
        }}
    }}
    if (s->stamped) {{
        step_ns = (uint64_t)t_ns - (uint64_t)s->last_ns; /* exact: t_ns > last_ns */
        if (GD_PERIOD_NS > 0) {{ /* against the sample's expected time on the time base */
            int gap;
            bstep = base_step(s);
            dev = deviation(s, step_ns, bstep, &gap);
            if (!gap && dev < GD_MIN_STEP_NS - GD_PERIOD_NS) {{
                s->n_early++; /* a sample that came: the rate's average counts it */
                s->early_since = 1;
                return GD_REFUSED_EARLY;
            }}
            if (gap || dev > GD_MAX_STEP_NS - GD_PERIOD_NS) {{
                gd_reset(s);
                code = GD_RESTARTED;
            }} else if (dev - bstep >= GD_MIN_STEP_NS - GD_PERIOD_NS &&
                       (int64_t)step_ns - 2 * bstep >= GD_MIN_STEP_NS - GD_PERIOD_NS) {{
                /* a step less the early tolerance late, two steps after the last sample taken: one sample missing,
                   stepped over; more than one in GD_MISSED_SHARE samples taken (besides the first): a gap */
                if ((uint64_t)GD_MISSED_SHARE * s->n_missed < s->n_steps + (uint64_t)GD_MISSED_SHARE) {{
                    missed = 1;
                }} else {{
                    gd_reset(s);
                    code = GD_RESTARTED;
                }}
            }}
        }} else {{
            if (step_ns < (uint64_t)GD_MIN_STEP_NS) return GD_REFUSED_EARLY;
            if (is_gap(s, step_ns)) {{
                gd_reset(s);
                code = GD_RESTARTED;
            }}
        }}
    }}
    step(s, imu, gyro_out, std_out);
    if (s->stamped) {{ /* a step of this stream (not its first sample) */
        s->steps_ns += step_ns;
        s->n_steps++;
        /* once, when the steps taken and the samples refused as early reach GD_RATE_WINDOW: the mean interval */
        if (GD_PERIOD_NS > 0 && !s->rate_checked && s->n_steps + s->n_early >= GD_RATE_WINDOW) {{
            const uint64_t n = s->n_steps + s->n_early, scaled = s->steps_ns * GD_RATE_WINDOW;
            s->rate_checked = 1;
            if (scaled < rate_sum_min * n || scaled > rate_sum_max * n) code = GD_RATE_OFF;
        }}
    }}
    if (s->stamped && GD_PERIOD_NS > 0) {{
        /* a step with a sample refused as early inside is left out of the track (the stream's jitter, or one sample
           too many?) */
        s->lag_ns = lag_after(missed ? dev - bstep : dev);
        s->n_missed += (uint64_t)missed;
        if (!s->early_since) {{
            s->track_ns += step_ns;
            s->track_n += 1 + (uint64_t)missed;
        }}
    }} else {{
        s->lag_ns = 0; /* a new stream, or without a rate: unused */
    }}
    s->late_in_a_row = 0;
    s->early_since = 0;
    s->stamped = 1;
    s->last_ns = t_ns;
    return code;
}}
"""
