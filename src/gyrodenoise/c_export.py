"""Plain C99 export of the streaming step, for targets without ONNX Runtime (microcontrollers, flight controllers).

    python -m gyrodenoise.export euroc --c OUT_DIR

writes OUT_DIR/gyrodenoise_model.h (the API: sizes as #defines, the state struct, gd_reset, gd_step and the stamped
gd_step_t, whose timestamp checks are `c_clock`'s), OUT_DIR/gyrodenoise_model.c (the weights as `static const float`
arrays, batch norm folded into the convolutions, and the code) and OUT_DIR/example_main.c (CSV on stdin -> corrected
gyro on stdout). The C code needs <math.h>, <string.h> and <stdint.h> only and allocates nothing: the state (one ring
buffer of inputs per dilated layer, the stream's last stamp) is one struct. It computes in float32 only (no double:
`c_targets` cross-compiles it for Cortex-M with -Wdouble-promotion -Werror and runs it under QEMU).

The arithmetic is the streaming corrector's (`gyrodenoise.streaming`): the weights written are those it folds, the
normalisation is (x - mean) * (1 / std), a stream's first sample fills every layer's history with its copies (the
batch model's replicate padding), and an ensemble outputs its members' mean and sample std (K - 1) x spread_scale.
All of it in float32, so the C outputs equal StreamingCorrector's and the batch model's to float32 rounding
(`c_parity` compiles the files and measures it; `python -m gyrodenoise.export --c` runs it when a compiler is found).
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import tempfile
from pathlib import Path

import numpy as np

from gyrodenoise import c_clock, provenance
from gyrodenoise.atomic import write_text
from gyrodenoise.c_example import UNSTAMPED, example_source
from gyrodenoise.data.checks import ACC_ABS_MAX, GYRO_ABS_MAX
from gyrodenoise.models.build import not_built_in
from gyrodenoise.models.ensemble import CorrectionModel, EnsembleCorrection, predict_with_spread
from gyrodenoise.pretrained import not_better_warning, sensor_model
from gyrodenoise.streaming import StreamingCorrector

HEADER, SOURCE, EXAMPLE = "gyrodenoise_model.h", "gyrodenoise_model.c", "example_main.c"
COMPILE = f"cc -O2 -std=c99 -o gyrodenoise {EXAMPLE} {SOURCE} -lm"
# C vs StreamingCorrector: both float32, summed in other orders; measured ~1e-7 rad/s (8-network `euroc`: 1.5e-7)
PARITY_TOL_RAD_S = 1e-5

# the model's activations (models/denoiser.py ACTIVATIONS) in C, with torch's default formulas
C_ACTIVATIONS = {
    "gelu": "0.5f * x * (1.0f + erff(x * 0.70710678118654752f))",
    "elu": "x > 0.0f ? x : expm1f(x)",
    "silu": "x / (1.0f + expf(-x))",
    "relu": "x > 0.0f ? x : 0.0f",
    "tanh": "tanhf(x)",
    "softplus": "x > 20.0f ? x : log1pf(expf(x))",  # torch's threshold 20: x itself above it
    "mish": "x * tanhf(x > 20.0f ? x : log1pf(expf(x)))",
}


# ---------------------------------------------------------------------------------------------- the model's numbers
def _members(model: CorrectionModel) -> list[StreamingCorrector]:
    """One float64 streaming corrector per member (its folded weights), or a one-line error for a model without a C
    form."""
    if what := not_built_in(model):
        raise ValueError(
            f"{what} has no C form: the C export implements the built-in denoiser and calibrated models (and their "
            "ensembles) only; export it to ONNX instead"
        )
    members = list(model.members) if isinstance(model, EnsembleCorrection) else [model]
    try:
        out = [StreamingCorrector(m, dtype="float64") for m in members]
    except TypeError as e:  # a layer or activation the streaming form does not know (models.net edited)
        raise ValueError(f"the model has no C form: {e}") from None
    for sc in out:
        if unknown := sorted({ly.act for ly in sc.layers} - set(C_ACTIVATIONS)):
            raise ValueError(f"activation {unknown[0]!r} has no C implementation (C export: {sorted(C_ACTIVATIONS)})")
        arrays = [sc.C_hat, sc.mean, sc.std, sc.head_w, sc.head_b, sc.constant]
        if not all(np.isfinite(a).all() for a in arrays + [a for ly in sc.layers for a in (ly.weight, ly.bias)]):
            raise ValueError("the model holds NaN/inf weights or statistics: nothing to export")
    return out


def _receptive_field(members: list[StreamingCorrector]) -> int:
    return max(sc.receptive_field for sc in members)


# ---------------------------------------------------------------------------------------------- C text pieces
def _float(v: float) -> str:
    """A float32 as a C literal that reads back to the same float32 (9 significant digits)."""
    s = f"{float(np.float32(v)):.9g}"
    return (s if any(ch in s for ch in ".e") else s + ".0") + "f"


def _array(name: str, values: np.ndarray, comment: str) -> str:
    flat = [_float(v) for v in np.asarray(values, dtype=np.float64).ravel()]
    rows = [", ".join(flat[i : i + 8]) for i in range(0, len(flat), 8)]
    body = ",\n    ".join(rows)
    return f"/* {comment} */\nstatic const float {name}[{len(flat)}] = {{\n    {body}\n}};\n"


def _member_arrays(k: int, sc: StreamingCorrector) -> str:
    """Member k's weights: normalisation, C_hat, each layer [out][tap][in] (tap 0 the oldest), the head."""
    parts = [
        _array(f"m{k}_mean", sc.mean, f"member {k}: input mean (gyro rad/s, acc m/s^2)"),
        _array(f"m{k}_inv_std", 1.0 / sc.std, f"member {k}: 1 / input std"),
        _array(f"m{k}_c_hat", sc.C_hat, f"member {k}: C_hat (3x3, row-major)"),
    ]
    for j, ly in enumerate(sc.layers):
        c_out, c_in, kernel = ly.weight.shape
        parts.append(
            _array(
                f"m{k}_l{j}_w",
                ly.weight.transpose(0, 2, 1),  # (C_out, C_in, k) -> [out][tap][in]: one dot product per output
                f"member {k}, layer {j}: conv {c_in} -> {c_out}, kernel {kernel}, dilation {ly.dilation}, {ly.act}; "
                "batch norm folded in; [out][tap][in], tap 0 the oldest",
            )
        )
        parts.append(_array(f"m{k}_l{j}_b", ly.bias, f"member {k}, layer {j}: bias (batch norm folded in)"))
    n_in = sc.head_w.shape[1]
    parts.append(_array(f"m{k}_head_w", sc.head_w, f"member {k}: head 1x1 conv {n_in} -> 3, x output scale [rad/s]"))
    bias = "bias x output scale" if sc.layers else "constant bias (+ G mean_acc)"
    parts.append(_array(f"m{k}_head_b", sc.head_b + sc.constant, f"member {k}: head {bias} [rad/s]"))
    return "\n".join(parts)


def _member_tables(members: list[StreamingCorrector]) -> tuple[str, int, int]:
    """The layer and member tables, the number of ring buffers and their total size in floats."""
    out, entries, ring, offset = [], [], 0, 0
    for k, sc in enumerate(members):
        rows = []
        for j, ly in enumerate(sc.layers):
            c_out, c_in, kernel = ly.weight.shape
            act = f"GD_ACT_{ly.act.upper()}"
            rows.append(f"    {{m{k}_l{j}_w, m{k}_l{j}_b, {c_in}, {c_out}, {kernel}, {ly.dilation}, {act}, {offset}}}")
            offset += ly.span * c_in
        layers = "NULL"
        if rows:
            out.append(f"static const gd_layer m{k}_layers[{len(rows)}] = {{\n" + ",\n".join(rows) + "\n};\n")
            layers = f"m{k}_layers"
        entries.append(
            f"    {{m{k}_mean, m{k}_inv_std, m{k}_c_hat, m{k}_head_w, m{k}_head_b, {layers}, {len(rows)}, "
            f"{sc.head_w.shape[1]}, {ring}}}"
        )
        ring += len(rows)
    out.append("static const gd_member gd_members[GD_N_MEMBERS] = {\n" + ",\n".join(entries) + "\n};\n")
    return "\n".join(out), ring, offset


def _memory_line(rf: int, rate: float) -> str:
    if rf == 1:
        return "Receptive field: 1 sample (no memory)"
    return (
        f"Receptive field: {rf} samples" + (f" ({rf / rate:.2f} s)" if rate else "") + "; a stream starts as if "
        f"preceded by\n  {rf - 1} copies of its first sample (the first ~{rf} outputs are less accurate)"
    )


def _size(n_bytes: int) -> str:
    return f"{n_bytes:,} bytes" if n_bytes < 10240 else f"{n_bytes / 1024:,.0f} KiB"


def _footprint(members: list[StreamingCorrector], sizes: dict) -> str:
    """Multiply-adds per sample, the state's RAM and the weights' flash."""
    macs = sum(sum(ly.weight.size for ly in sc.layers) + sc.head_w.size + 9 for sc in members)
    floats = max(sizes["ring_floats"], 1) + 2 * sizes["max_channels"] + 3 * len(members)
    ram = 4 * floats + 4 * (max(sizes["n_rings"], 1) + 2) + 24  # + the stream's stamps (gd_step_t)
    n_weights = sum(
        2 * sc.mean.size + 9 + sc.head_w.size + 3 + sum(ly.weight.size + ly.bias.size for ly in sc.layers)
        for sc in members
    )
    return (
        f"Cost: {macs:,} multiply-adds per sample; RAM: the state, about {_size(ram)};\n"
        f"  flash: {n_weights:,} float weights ({_size(4 * n_weights)})."
    )


def _describe(model: CorrectionModel, members: list[StreamingCorrector], meta: dict) -> list[str]:
    """The header comment's lines about the model: name, sensor, rate, units, receptive field, origin."""
    sensor = sensor_model(meta)
    rate = meta.get("rate_hz") or (meta.get("sensor") or {}).get("rate_hz")
    rf = _receptive_field(members)
    kind = f"ensemble of {len(members)} members" if isinstance(model, EnsembleCorrection) else type(model).__name__
    lines = [
        f"Model: {meta.get('name', '(unnamed)')} ({kind}"
        + (f", trained on {meta['dataset']}" if meta.get("dataset") else "")
        + ")",
        f"Sensor: {sensor or 'not recorded'}"
        + (": learned the errors of this IMU model; another IMU needs its own model" if sensor else ""),
        f"Rate: {float(rate):g} Hz: feed consecutive samples at this rate" if rate else "Rate: not recorded",
        "Units: input gyro x, y, z [rad/s] then accelerometer x, y, z [m/s^2] (specific force, gravity included:",
        "  about +9.81 m/s^2 up at rest), IMU body frame; output corrected gyro x, y, z [rad/s]"
        + (
            ",\n  and the members' spread per axis: sample std (K - 1) x spread_scale [rad/s]"
            if len(members) > 1
            else ""
        ),
        _memory_line(rf, float(rate or 0)),
        f"Exported by {provenance.code_version_text()} (python -m gyrodenoise.export ... --c)",
    ]
    if meta.get("path"):
        lines.append(f"From the model file: {Path(meta['path']).name}")
    if warning := not_better_warning(meta):
        lines.append(f"WARNING: {warning}")
    return lines


# ---------------------------------------------------------------------------------------------- the files
HEADER_API = """\
#ifndef GYRODENOISE_MODEL_H
#define GYRODENOISE_MODEL_H

#include <stdint.h>

#ifdef __cplusplus
extern "C" {{ /* C++ callers link the C-compiled gyrodenoise_model.c */
#endif

{defines}

{clock_defines}

/* One stream's state: sizeof(gd_state) bytes of RAM, no allocation. A zeroed (static) state is a reset one. */
typedef struct gd_state {{
    float ring[GD_RING_FLOATS > 0 ? GD_RING_FLOATS : 1]; /* each dilated layer's last dilation*(k-1)+1 inputs */
    int newest[GD_N_RINGS > 0 ? GD_N_RINGS : 1];          /* row of the newest input in each ring */
    int started;                                          /* 0: the next sample starts a stream */
    float work[2][GD_MAX_CHANNELS];                       /* scratch of one step */
    float member_out[GD_N_MEMBERS][3];                    /* each member's corrected gyro of the last step */
{state_fields}
}} gd_state;

/* Forget the past: the next gd_step's sample starts a stream and fills every layer's history with copies of
   itself (as the batch model's padding and gyrodenoise.streaming.StreamingCorrector.reset()). Call it before the
   first sample (or zero the state) and after a gap in the stream. */
void gd_reset(gd_state *s);

/* Consume one sample imu = {{gx, gy, gz [rad/s], ax, ay, az [m/s^2]}}; write the corrected gyro [rad/s] to gyro_out
   and, when std_out is not NULL, the members' spread per axis [rad/s] (NaN for one network: no spread).
   Returns GD_OK (0), or GD_REFUSED_SAMPLE (-1) when the sample holds a NaN/inf or a value beyond GD_GYRO_ABS_MAX /
   GD_ACC_ABS_MAX: it would spoil a receptive field of outputs, so it is refused and the state is left unchanged
   (nothing is written); GD_REFUSED_UNSTAMPED (-4) on a stream gd_step_t stamped. Timestamps are not checked: feed
   consecutive samples at GD_RATE_HZ, gd_reset after a gap. A state used before gd_reset (or zeroing) is undefined:
   its ring indices may point anywhere. */
int gd_step(gd_state *s, const float imu[6], float gyro_out[3], float *std_out);

{declaration}

#ifdef __cplusplus
}}
#endif

#endif /* GYRODENOISE_MODEL_H */
"""

SOURCE_CODE = """\
enum {{ {act_enum} }};

typedef struct {{
    const float *w, *b;        /* [out][tap][in] weights, bias */
    int c_in, c_out, kernel, dilation, act;
    int ring;                  /* offset of its ring buffer in gd_state.ring: (dilation*(kernel-1)+1) x c_in */
}} gd_layer;

typedef struct {{
    const float *mean, *inv_std, *c_hat, *head_w, *head_b;
    const gd_layer *layers;
    int n_layers, head_in;     /* head_in: the head's input width (6: no layers, the normalised sample) */
    int first_ring;            /* index of its first layer in gd_state.newest */
}} gd_member;

{arrays}
{tables}
static const float spread_scale = {spread_scale};

static float activate(int act, float x)
{{
    switch (act) {{
{act_cases}
    }}
    return x;
}}

/* y[o] = act(b[o] + sum over the taps, oldest first, of W[o][tap] . x[tap]); tap i is row
   newest - (kernel-1-i)*dilation. One dot product per output, its sums in registers (weights [out][tap][in], read
   once, in order), over eight independent partial sums: no chain of dependent multiply-adds. */
static void conv_step(const gd_layer *L, const float *ring, int newest, float *restrict y)
{{
    const int rows = L->dilation * (L->kernel - 1) + 1;
    const float *w = L->w;
    for (int o = 0; o < L->c_out; o++) {{
        float a0 = L->b[o], a1 = 0.0f, a2 = 0.0f, a3 = 0.0f, a4 = 0.0f, a5 = 0.0f, a6 = 0.0f, a7 = 0.0f;
        for (int i = 0; i < L->kernel; i++, w += L->c_in) {{
            int r = newest - (L->kernel - 1 - i) * L->dilation;
            if (r < 0) r += rows;
            const float *x = ring + (size_t)r * (size_t)L->c_in;
            int c = 0;
            for (; c + 8 <= L->c_in; c += 8) {{
                a0 += w[c] * x[c];
                a1 += w[c + 1] * x[c + 1];
                a2 += w[c + 2] * x[c + 2];
                a3 += w[c + 3] * x[c + 3];
                a4 += w[c + 4] * x[c + 4];
                a5 += w[c + 5] * x[c + 5];
                a6 += w[c + 6] * x[c + 6];
                a7 += w[c + 7] * x[c + 7];
            }}
            for (; c < L->c_in; c++) a0 += w[c] * x[c];
        }}
        y[o] = activate(L->act, ((a0 + a4) + (a2 + a6)) + ((a1 + a5) + (a3 + a7)));
    }}
}}

/* Write h as the layer's newest input; at a stream's start, first fill its whole history with h (a constant
   input gives a constant output, so every later layer's history is filled with copies of its first input too). */
static int push_input(const gd_layer *L, float *ring, int newest, const float *h, int start)
{{
    const int rows = L->dilation * (L->kernel - 1) + 1;
    const size_t bytes = (size_t)L->c_in * sizeof *h;
    if (start)
        for (int r = 0; r < rows; r++) memcpy(ring + (size_t)r * (size_t)L->c_in, h, bytes);
    newest = newest + 1 == rows ? 0 : newest + 1;
    memcpy(ring + (size_t)newest * (size_t)L->c_in, h, bytes);
    return newest;
}}

static void member_step(const gd_member *m, gd_state *s, const float imu[6], int start, float out[3])
{{
    float *h = s->work[0], *y = s->work[1];
    for (int c = 0; c < 6; c++) h[c] = (imu[c] - m->mean[c]) * m->inv_std[c];
    for (int j = 0; j < m->n_layers; j++) {{
        const gd_layer *L = &m->layers[j];
        int *newest = &s->newest[m->first_ring + j];
        *newest = push_input(L, s->ring + L->ring, *newest, h, start);
        conv_step(L, s->ring + L->ring, *newest, y);
        float *t = h; h = y; y = t;
    }}
    for (int a = 0; a < 3; a++) {{
        const float *c_hat = m->c_hat + 3 * a, *w = m->head_w + (size_t)a * (size_t)m->head_in;
        float head = 0.0f;
        for (int c = 0; c < m->head_in; c++) head += w[c] * h[c];
        out[a] = (c_hat[0] * imu[0] + c_hat[1] * imu[1] + c_hat[2] * imu[2]) + head + m->head_b[a];
    }}
}}

/* NaN and inf by their bits: -ffast-math (-ffinite-math-only) lets a compiler fold isfinite() to 1 */
static int finite_bits(float x)
{{
    uint32_t u;
    memcpy(&u, &x, sizeof u);
    return (u & UINT32_C(0x7f800000)) != UINT32_C(0x7f800000);
}}

static int sample_ok(const float imu[6])
{{
    for (int c = 0; c < 6; c++) {{
        const float limit = c < 3 ? GD_GYRO_ABS_MAX : GD_ACC_ABS_MAX;
        if (!finite_bits(imu[c]) || fabsf(imu[c]) > limit) return 0;
    }}
    return 1;
}}

/* a quiet NaN from its bits (NAN itself is folded away or warned about under -ffast-math): one network's "spread" */
static float no_spread(void)
{{
    const uint32_t u = UINT32_C(0x7fc00000);
    float x;
    memcpy(&x, &u, sizeof x);
    return x;
}}

/* one step of a checked sample: every member, then their mean and spread */
static void step(gd_state *s, const float imu[6], float gyro_out[3], float *std_out)
{{
    for (int k = 0; k < GD_N_MEMBERS; k++) member_step(&gd_members[k], s, imu, !s->started, s->member_out[k]);
    s->started = 1;
    for (int a = 0; a < 3; a++) {{
        float sum = 0.0f, sq = 0.0f;
        for (int k = 0; k < GD_N_MEMBERS; k++) sum += s->member_out[k][a];
        const float mean = sum / GD_N_MEMBERS;
        for (int k = 0; k < GD_N_MEMBERS; k++) sq += (s->member_out[k][a] - mean) * (s->member_out[k][a] - mean);
        gyro_out[a] = mean;
        if (std_out) std_out[a] = GD_N_MEMBERS > 1 ? sqrtf(sq / (GD_N_MEMBERS - 1)) * spread_scale : no_spread();
    }}
}}

{clock_code}"""

DEFINES = (  # name, value key, comment
    ("GD_N_MEMBERS", "n_members", "networks averaged (an ensemble: > 1)"),
    ("GD_N_RINGS", "n_rings", "dilated layers over all members: one ring buffer of inputs each"),
    ("GD_RING_FLOATS", "ring_floats", "the ring buffers' total size (floats)"),
    ("GD_MAX_CHANNELS", "max_channels", "widest layer"),
    ("GD_RECEPTIVE_FIELD", "rf", "samples an output depends on"),
    ("GD_RATE_HZ", "rate", "the training rate (0: not recorded)"),
    ("GD_GYRO_ABS_MAX", "gyro_max", "|gyro| [rad/s] above this: the sample is refused"),
    ("GD_ACC_ABS_MAX", "acc_max", "|acc| [m/s^2] above this: the sample is refused"),
)


def _defines(sizes: dict) -> str:
    return "\n".join(f"#define {name:<19} {str(sizes[key]):<10} /* {text} */" for name, key, text in DEFINES)


def _header(model: CorrectionModel, members: list[StreamingCorrector], meta: dict, sizes: dict) -> str:
    ensemble = len(members) > 1
    std_arg = "std" if ensemble else "NULL"
    usage = [
        "",
        "Use (C99, <math.h>, <string.h> and <stdint.h> only, no allocation):",
        '    #include "gyrodenoise_model.h"',
        "    static gd_state st;                  // one per stream; zeroed = reset",
        "    float imu[6] = {gx, gy, gz, ax, ay, az}, w[3]" + (", std[3];" if ensemble else ";"),
        f"    int code = gd_step_t(&st, t_ns, imu, w, {std_arg});  // t_ns: the sample's stamp, int64 nanoseconds",
        "    if (code < 0) { ... }                // refused (GD_REFUSED_*): state unchanged, drop the sample",
        "    else { ... }                         // w written (GD_RESTARTED: after a gap; GD_RATE_OFF: rate off)",
        f"  Without stamps: gd_step(&st, imu, w, {std_arg}), and gd_reset(&st) after a gap.",
        _footprint(members, sizes),
        f"Example: {EXAMPLE} (CSV on stdin); compile:\n    {COMPILE}",
        "Outputs equal gyrodenoise's StreamingCorrector and batch model to float32 rounding (~1e-7 rad/s).",
    ]
    lines = ["gyrodenoise gyro correction, plain C99 export", "", *_describe(model, members, meta), *usage]
    # nothing from the metadata may end the comment, nor open one inside it (gcc -Wall: "/*" within comment)
    text = "\n".join(lines).replace("*/", "* /").replace("/*", "/ *")
    comment = "\n".join(f" * {s}".rstrip() for s in text.splitlines())
    api = HEADER_API.format(
        defines=_defines(sizes),
        clock_defines=c_clock.header_defines(sizes["rate_hz"], sizes["rf"] > 1),
        state_fields=c_clock.STATE_FIELDS,
        declaration=c_clock.DECLARATION,
    )
    return f"/*\n{comment}\n */\n" + api


def _source(members: list[StreamingCorrector], spread_scale: float, sizes: dict) -> str:
    tables, _, _ = _member_tables(members)
    names = list(C_ACTIVATIONS)
    cases = "\n".join(f"    case GD_ACT_{n.upper()}: return {C_ACTIVATIONS[n]};" for n in names)
    code = SOURCE_CODE.format(
        act_enum=", ".join(f"GD_ACT_{n.upper()}" for n in names),
        arrays="\n".join(_member_arrays(k, sc) for k, sc in enumerate(members)),
        tables=tables,
        spread_scale=_float(spread_scale),
        act_cases=cases,
        clock_code=c_clock.source_code(sizes["rate_hz"], sizes["rf"] > 1),
    )
    head = (
        "/* gyrodenoise gyro correction: weights and code (generated by python -m gyrodenoise.export --c; "
        f"see {HEADER}) */\n"
    )
    return head + f'#include <math.h>\n#include <string.h>\n\n#include "{HEADER}"\n\n' + code


DEFAULT_PREFIX = "gd"
_IDENTIFIER = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


def with_prefix(text: str, prefix: str) -> str:
    """The generated code with its public names (gd_step, gd_reset, gd_state, GD_* sizes, the header guard) under
    another prefix, so that two exported models link into one program."""
    if prefix == DEFAULT_PREFIX:
        return text
    if not _IDENTIFIER.fullmatch(prefix):
        raise ValueError(f"--c-prefix {prefix!r}: a C identifier (letters, digits, _; not starting with a digit)")
    text = re.sub(r"\bgd_", f"{prefix}_", text)
    text = re.sub(r"\bGD_", f"{prefix.upper()}_", text)
    return text.replace("GYRODENOISE_MODEL_H", f"{prefix.upper()}_GYRODENOISE_MODEL_H")


def c_sources(model: CorrectionModel, meta: dict | None = None, prefix: str = DEFAULT_PREFIX) -> dict[str, str]:
    """{file name: text} of the C export (see the module docstring), its public names prefixed with `prefix`
    (default gd_); ValueError for a model without a C form."""
    with_prefix("", prefix)  # a bad prefix before any work
    meta = meta or {}
    members = _members(model)
    _, n_rings, ring_floats = _member_tables(members)
    rate = meta.get("rate_hz") or (meta.get("sensor") or {}).get("rate_hz") or 0.0
    sizes = {
        "n_members": len(members),
        "n_rings": n_rings,
        "ring_floats": ring_floats,
        "max_channels": max([6] + [ly.weight.shape[0] for sc in members for ly in sc.layers]),
        "rf": _receptive_field(members),
        "rate": f"{float(rate):.6g}" + ("" if "." in f"{float(rate):.6g}" else ".0"),
        "rate_hz": float(rate),
        "gyro_max": f"{GYRO_ABS_MAX:.1f}f",
        "acc_max": f"{ACC_ABS_MAX:.1f}f",
    }
    spread = float(getattr(model, "spread_scale", 1.0))
    files = {
        HEADER: _header(model, members, meta, sizes),
        SOURCE: _source(members, spread, sizes),
        EXAMPLE: example_source(len(members) > 1, COMPILE),
    }
    return {name: with_prefix(text, prefix) for name, text in files.items()}


def export_c(
    model: CorrectionModel, out_dir: str | Path, meta: dict | None = None, prefix: str = DEFAULT_PREFIX
) -> list[Path]:
    """Write the C export's three files into out_dir (created if missing), public names prefixed with `prefix`;
    returns their paths."""
    out_dir = Path(out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise ValueError(f"--c {out_dir} is a file: give a folder to write {HEADER}, {SOURCE} and {EXAMPLE} into")
    sources = c_sources(model, meta, prefix)
    try:
        return [write_text(out_dir / name, text) for name, text in sources.items()]
    except OSError as e:  # a read-only or unwritable place, a file on the way: one line, not a traceback
        raise ValueError(f"--c {out_dir}: cannot write the C files there ({e.strerror or e})") from None


# ---------------------------------------------------------------------------------------------- compile and compare
def find_c_compiler() -> str | None:
    """$CC, else cc, gcc or clang on the PATH (None: no C compiler)."""
    if os.environ.get("CC") and shutil.which(os.environ["CC"].split()[0]):
        return os.environ["CC"]
    return next((c for c in ("cc", "gcc", "clang") if shutil.which(c)), None)


def compile_example(
    out_dir: str | Path, exe: str | Path, compiler: str | None = None, werror: bool = False, opt: str = "-O2"
) -> Path:
    """Compile out_dir's example_main.c and the model into `exe` (cc -O2 -std=c99 -Wall -Wextra -pedantic ... -lm;
    `werror`: warnings are errors). RuntimeError with the compiler's messages when it fails."""
    cc = compiler or find_c_compiler()
    if cc is None:
        raise FileNotFoundError("no C compiler found (cc, gcc, clang, or $CC)")
    out_dir = Path(out_dir)
    strict = ["-Werror"] if werror else []
    cmd = [*cc.split(), opt, "-std=c99", "-Wall", "-Wextra", "-pedantic", *strict, "-o", str(exe)]
    cmd += [str(out_dir / EXAMPLE), str(out_dir / SOURCE), "-lm"]
    done = subprocess.run(cmd, capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed:\n{done.stderr[-4000:]}")
    return Path(exe)


def example_input(imu: np.ndarray, t_ns: np.ndarray | None = None) -> str:
    """The example's CSV input: (N, 6) samples as float32, written exactly, after their stamps (default 0..N-1)."""
    x = np.asarray(imu, dtype=np.float32).tolist()
    t = range(len(x)) if t_ns is None else np.asarray(t_ns, dtype=np.int64).tolist()
    rows = (f"{s}," + ",".join(f"{v:.9g}" for v in row) + "\n" for s, row in zip(t, x, strict=True))
    return "t,gx,gy,gz,ax,ay,az\n" + "".join(rows)


def example_output(stdout: str, n: int, what: str) -> tuple[np.ndarray, np.ndarray | None]:
    """(gyro (n, 3), std (n, 3) or None) from the example's output; RuntimeError naming `what` unless n lines."""
    lines = stdout.splitlines()[1:]
    if len(lines) != n:
        raise RuntimeError(f"{what} wrote {len(lines)} lines for {n} samples")
    rows = np.array([[float(v) for v in ln.split(",")] for ln in lines])
    return rows[:, 1:4], (rows[:, 4:7] if rows.shape[1] == 7 else None)


def run_example(
    exe: str | Path, imu: np.ndarray, t_ns: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray | None]:
    """Feed (N, 6) samples to a compiled example; (gyro (N, 3), std (N, 3) or None). t_ns: (N,) int64 stamps, the
    stamped step (gd_step_t; every sample must be taken); None: `--unstamped`, the samples taken as consecutive."""
    cmd = [str(exe)] + ([UNSTAMPED] if t_ns is None else [])
    try:
        done = subprocess.run(cmd, input=example_input(imu, t_ns), capture_output=True, text=True)
    except OSError as e:  # built for another machine: $CC a cross compiler
        raise RuntimeError(f"{exe} cannot run here: {e.strerror} (is $CC a cross compiler?)") from None
    if done.returncode != 0:
        raise RuntimeError(f"{exe} failed: {done.stderr.strip()}")
    return example_output(done.stdout, len(imu), str(exe))


def stream_reference(model: CorrectionModel, imu: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
    """StreamingCorrector (float32, one sample per push) on the same float32 samples."""
    sc = StreamingCorrector(model)
    outs = [sc.push_with_spread(s) for s in np.asarray(imu, dtype=np.float32)]
    std = None if outs[0][1] is None else np.stack([o[1] for o in outs])
    return np.stack([o[0] for o in outs]), std


def c_parity(
    model: CorrectionModel,
    out_dir: str | Path,
    imu: np.ndarray | None = None,
    n: int = 1500,
    compiler: str | None = None,
    werror: bool = False,
) -> dict[str, float]:
    """Compile out_dir's files, run them on `imu` (default: n random IMU-like samples) and return the max |C -
    StreamingCorrector| over the gyro ('gyro') and, for an ensemble, the std ('std'), and the max |C - the batch
    model| over the gyro ('gyro_batch': the streaming corrector folds batch norm as the export does, the batch model
    does not), in rad/s."""
    if imu is None:
        rng = np.random.default_rng(0)
        imu = np.concatenate([rng.normal(0, 0.5, (n, 3)), rng.normal(0, 1, (n, 3)) + [0, 0, 9.81]], axis=1)
    with tempfile.TemporaryDirectory() as tmp:
        exe = compile_example(out_dir, Path(tmp) / "gyrodenoise", compiler, werror)
        gyro, std = run_example(exe, imu)
    ref, ref_std = stream_reference(model, imu)
    batch, _ = predict_with_spread(model, np.asarray(imu, dtype=np.float32))
    out = {"gyro": float(np.abs(gyro - ref).max()), "gyro_batch": float(np.abs(gyro - batch).max())}
    if ref_std is not None:  # none for one member: the streaming corrector gives no std, the C example writes none
        out["std"] = float(np.abs(std - ref_std).max())
    return out
