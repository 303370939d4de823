"""Causal streaming inference: correct the gyro sample by sample (or chunk by chunk), as onboard.

The batch model pads the whole sequence on the left by replicating its first sample, then runs
"valid" dilated convolutions. Streaming keeps, per conv layer, a ring buffer of the layer's last
dilation*(k-1) inputs, so one new sample costs one k-tap dot product per layer: O(1) per sample,
whatever the sequence length. The initial state is what the batch model computes on its padding:
every layer fed a constant input (the first sample) outputs a constant, so each buffer starts as
that constant repeated. Outputs therefore match `predict_gyro` from the first sample on.

Batch norm (eval mode) is folded into its convolution; dropout is the identity at inference.

    sc = StreamingCorrector(model)          # a trained GyroCorrection or EnsembleCorrection
    w = sc.push(imu_sample)                 # (6,) raw gyro rad/s + acc m/s^2 -> (3,) rad/s
    W = sc.push_chunk(imu_block)            # (N, 6) -> (N, 3), same state
    w, s = sc.push_with_spread(imu_sample)  # an ensemble: mean and std over its members

    sc = StreamingCorrector.load("euroc")   # a shipped name or a model file; knows the training rate
    w = sc.push(imu_sample, t_ns=stamp)     # timestamps checked: order, gaps, rate (`stream_clock`)

An ensemble streams as one state per member; the output is the members' mean and their sample
standard deviation (K - 1 denominator) times its `spread_scale`, as `EnsembleCorrection.forward_with_spread`.
"""

from __future__ import annotations

import copy
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import torch
from numpy.lib.stride_tricks import sliding_window_view
from scipy import special
from torch import nn

from gyrodenoise.data.checks import ACC_ABS_MAX, GYRO_ABS_MAX, GYRO_P99_MAX, SanityWarning, gravity_norm
from gyrodenoise.data.gyro_scale import gyro_scale_verdict, gyro_unit_message
from gyrodenoise.models.build import check_stream_form
from gyrodenoise.models.denoiser import ACTIVATIONS, DilatedCNNDenoiser
from gyrodenoise.models.ensemble import CorrectionModel, EnsembleCorrection
from gyrodenoise.stream_clock import StreamClock

UNIT_PROBE = 400  # samples (2 s at 200 Hz) before the accelerometer's unit is judged, once per stream
GYRO_PROBE_S = 30.0  # seconds of a stream's start over which the gyro's unit is read off gravity, once per stream

ArrayLike = np.ndarray | torch.Tensor | Sequence[float]  # one sample (6,) or a chunk (N, 6)
StampLike = int | np.ndarray | Sequence[int] | None  # int64 ns: one stamp, or one per sample of a chunk

BACKENDS = ("numpy", "torch")


def _softplus(x: np.ndarray) -> np.ndarray:
    return np.logaddexp(x, 0.0).astype(x.dtype, copy=False)


# numpy twins of the torch activations (same formulas as torch's defaults)
NUMPY_ACTIVATIONS: dict[str, Callable[[np.ndarray], np.ndarray]] = {
    "gelu": lambda x: 0.5 * x * (1.0 + special.erf(x * np.float32(1.0 / np.sqrt(2.0)))),
    "elu": lambda x: np.where(x > 0, x, np.expm1(np.minimum(x, 0))),
    "silu": lambda x: x * special.expit(x),
    "relu": lambda x: np.maximum(x, 0),
    "tanh": np.tanh,
    "softplus": _softplus,
    "mish": lambda x: x * np.tanh(_softplus(x)),
}


def _checked(x, dtype, what: str) -> np.ndarray:
    """`x` as `dtype`, refused before the state changes when a value is NaN/inf (also after the cast: 1e39 is inf in
    float32) or beyond what any IMU measures: it would enter every layer's buffer and spoil the outputs of a whole
    receptive field (~2.5 s) after it, without an error."""
    x = np.asarray(x, dtype=dtype)
    bad = ~np.isfinite(x)
    if bad.any():  # (a wrong shape is left to the caller's message)
        problem = "a NaN/inf IMU value"
    elif x.size and x.shape[-1] == 6:
        bad = np.concatenate([np.abs(x[..., :3]) > GYRO_ABS_MAX, np.abs(x[..., 3:]) > ACC_ABS_MAX], axis=-1)
        problem = (
            f"an IMU value beyond any sensor's range (|gyro| > {GYRO_ABS_MAX:g} rad/s or |acc| > {ACC_ABS_MAX:g} m/s^2)"
        )
    if not bad.any():
        return x
    where = f" in sample {int(np.argmax(bad.reshape(len(x), -1).any(axis=1))) + 1} of this call (counting from 1)"
    raise ValueError(
        f"{what}: {problem}{where if x.ndim == 2 else ''} would corrupt the outputs of the next receptive field "
        "(~2.5 s at 200 Hz) without an error; repair or drop the sample first (the state is unchanged)"
    )


@dataclass
class _Layer:
    """One dilated conv (batch norm folded in) followed by an activation."""

    weight: np.ndarray  # (C_out, C_in, k)
    bias: np.ndarray  # (C_out,)
    dilation: int
    act: str

    @property
    def kernel_size(self) -> int:
        return self.weight.shape[2]

    @property
    def span(self) -> int:
        """Number of inputs the output at time t depends on: t - span + 1 .. t."""
        return self.dilation * (self.kernel_size - 1) + 1


def _act_name(module: nn.Module) -> str:
    for name, cls in ACTIVATIONS.items():
        if type(module) is cls:
            return name
    raise TypeError(f"activation {type(module).__name__} has no streaming implementation")


def _fold(model: DilatedCNNDenoiser) -> tuple[list[_Layer], np.ndarray, np.ndarray]:
    """Walk model.net (Conv1d [BatchNorm1d] act Dropout)* Conv1d_head; fold BN into the conv."""
    mods = list(model.net)
    head = mods.pop()
    if not (isinstance(head, nn.Conv1d) and head.kernel_size == (1,)):
        raise TypeError("the last module of model.net must be the 1x1 head convolution")
    layers: list[_Layer] = []
    i = 0
    while i < len(mods):
        conv = mods[i]
        if not isinstance(conv, nn.Conv1d):
            raise TypeError(f"model.net[{i}] is {type(conv).__name__}, expected Conv1d")
        w = conv.weight.detach().double()
        b = conv.bias.detach().double() if conv.bias is not None else torch.zeros(w.shape[0], dtype=w.dtype)
        i += 1
        if isinstance(mods[i], nn.BatchNorm1d):
            bn = mods[i]
            scale = bn.weight.detach().double() / torch.sqrt(bn.running_var.double() + bn.eps)
            w = w * scale[:, None, None]
            b = (b - bn.running_mean.double()) * scale + bn.bias.detach().double()
            i += 1
        act = _act_name(mods[i])
        i += 1
        if i < len(mods) and isinstance(mods[i], nn.Dropout):
            i += 1
        layers.append(_Layer(w.numpy(), b.numpy(), conv.dilation[0], act))
    # output_scale: a float or a per-axis (3,) buffer, depending on the model version
    scale = torch.as_tensor(model.output_scale, dtype=torch.float64).detach().cpu().expand(3)
    hw = (head.weight.detach().double()[:, :, 0] * scale[:, None]).numpy()
    hb = (head.bias.detach().double() * scale).numpy()
    return layers, hw, hb


class StreamingCorrector:
    """Stateful causal gyro corrector, equal to the batch model run on everything pushed so far.

    backend: "numpy" (fastest for single samples) or "torch". dtype: float32 (as the batch model
    runs) or float64. Outputs are float64 rad/s. rate_hz: the model's training rate, against which
    the timestamps given to `push`/`push_chunk` (optional, int ns) are checked; by default the rate a model from
    `gyrodenoise.pretrained.load_model` records (`load` sets it too).
    """

    def __init__(
        self, model: CorrectionModel, backend: str = "numpy", dtype: str = "float32", rate_hz: float | None = None
    ) -> None:
        if backend not in BACKENDS:
            raise ValueError(f"backend={backend!r}; choose one of {BACKENDS}")
        self.backend = backend
        check_stream_form(model)
        self.members: list[StreamingCorrector] | None = None  # an ensemble: one streaming state per member
        if isinstance(model, EnsembleCorrection):
            self.members = [StreamingCorrector(m, backend, dtype) for m in model.members]
            self.spread_scale = model.spread_scale
            self.receptive_field = max(m.receptive_field for m in self.members)
        else:
            self._read_weights(model, dtype)
            self._prepare()
        if rate_hz is None:  # a model from load_model knows the rate its file records
            rate_hz = getattr(model, "training_rate_hz", None)
        memory = self.receptive_field > 1  # a memoryless model (calibrated) is blind to gaps and to the rate
        self.clock = StreamClock(rate_hz if memory else None, gaps=memory)
        self.reset()

    def _read_weights(self, model: CorrectionModel, dtype: str) -> None:
        """One member's input normalisation, C_hat and layers (batch norm folded), in float64."""
        self.np_dtype = np.dtype(dtype)
        self.t_dtype = {np.dtype("float32"): torch.float32, np.dtype("float64"): torch.float64}[self.np_dtype]
        model = copy.deepcopy(model).cpu()  # read the weights without moving the caller's model
        self.C_hat = model.C_hat.detach().double().numpy()
        self.mean = model.mean.detach().double().numpy()
        self.std = model.std.detach().double().numpy()
        if isinstance(model, DilatedCNNDenoiser):
            self.layers, self.head_w, self.head_b = _fold(model)
            self.constant = np.zeros(3)
        else:  # CalibratedImu
            self.layers, self.head_w, self.head_b = [], np.zeros((3, 6)), np.zeros(3)
            self.constant = model.bias.detach().double().numpy()
            if model.G is not None:  # G a = (G diag(std_a)) h_a + G mean_a on the normalised input h
                G = model.G.detach().double().numpy()
                self.head_w[:, 3:] = G * self.std[3:]
                self.constant = self.constant + G @ self.mean[3:]
        self.receptive_field = 1 + sum(ly.span - 1 for ly in self.layers)

    @classmethod
    def load(cls, model: str, backend: str = "numpy", dtype: str = "float32") -> StreamingCorrector:
        """A shipped model name (e.g. "euroc") or a model file, with the training rate its file records."""
        from gyrodenoise.pretrained import load_model, model_rate

        net, meta = load_model(model)
        return cls(net, backend, dtype, model_rate(meta))

    # ------------------------------------------------------------------ setup
    def _prepare(self) -> None:
        dt = self.np_dtype
        # numpy per-sample path: weights flattened tap-major, matching buffer[window][::d].ravel()
        self._w_flat = [ly.weight.transpose(0, 2, 1).reshape(ly.weight.shape[0], -1).astype(dt) for ly in self.layers]
        self._b = [ly.bias.astype(dt) for ly in self.layers]
        self._acts_np = [NUMPY_ACTIVATIONS[ly.act] for ly in self.layers]
        self._head_w = self.head_w.astype(dt)
        self._head_b = (self.head_b + self.constant).astype(dt)
        self._mean, self._inv_std = self.mean.astype(dt), (1.0 / self.std).astype(dt)
        self._C = self.C_hat.astype(dt)
        if self.backend == "torch":
            to = lambda a: torch.from_numpy(np.ascontiguousarray(a))  # noqa: E731
            self._t_w_flat = [to(w) for w in self._w_flat]
            self._t_w = [to(ly.weight.astype(dt)) for ly in self.layers]
            self._t_b = [to(b) for b in self._b]
            self._t_acts = [ACTIVATIONS[ly.act]() for ly in self.layers]
            self._t_head_w, self._t_head_b = to(self._head_w), to(self._head_b)
            self._t_mean, self._t_inv_std, self._t_C = to(self._mean), to(self._inv_std), to(self._C)

    def reset(self) -> None:
        """Forget the past: the next sample pushed is treated as the first of a sequence."""
        for m in self.members or []:
            m.reset()
        self.clock.reset()
        self._unit_probe: list[np.ndarray] | None = []  # the stream's first samples, for the sensors' units
        self._unit_probe_n = 0
        self._acc_judged = False
        self._buf: list = []
        self._pos = 0
        self.n_pushed = 0

    def _init_state(self, x0: np.ndarray) -> None:
        """Buffers as if the sequence had been preceded by copies of its first sample."""
        v = x0.astype(np.float64)
        self._buf, self._len = [], []
        for ly in self.layers:
            L = ly.span
            self._len.append(L)
            # doubled ring buffer: row i and i+L hold the same sample, so a window is one slice
            buf = np.broadcast_to(v, (2 * L, len(v))).astype(self.np_dtype)
            self._buf.append(torch.from_numpy(buf) if self.backend == "torch" else buf)
            v = NUMPY_ACTIVATIONS[ly.act](ly.weight.sum(2) @ v + ly.bias)
        self._pos = [ly.span - 1 for ly in self.layers]  # index of the newest row

    # ------------------------------------------------------------------ ensembles
    def _mean_std(self, outs: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray | None]:
        if len(outs) == 1:  # one member measures no spread: none, as `predict_with_spread`
            return outs[0], None
        stack = np.stack(outs)
        return stack.mean(0), stack.std(0, ddof=1) * self.spread_scale

    def _stamps(self, t_ns, n: int) -> np.ndarray | int | None:
        """The call's timestamps, checked against the stream's before anything changes (None: not given)."""
        if t_ns is None:
            if self.clock.last_ns is not None:
                raise ValueError("this stream was given timestamps: give t_ns with every push (or reset() first)")
            return None
        return self.clock.check(t_ns, n)

    def _run(self, sample, t_ns, chunk: bool) -> tuple[np.ndarray, np.ndarray | None]:
        """Check the input and its stamps once (for all members), push, and record the stamps."""
        what = "push_chunk" if chunk else "push"
        dtype = (self.members[0] if self.members else self).np_dtype
        x = _checked(sample, dtype, what)
        t = self._stamps(t_ns, len(x) if chunk and x.ndim == 2 else 1)
        one = StreamingCorrector._push_chunk_checked if chunk else StreamingCorrector._push_checked
        if self.members is None:
            out, std = one(self, x), None
        else:
            outs = [one(m, x) for m in self.members]
            self.n_pushed += len(outs[0]) if chunk else 1
            out, std = self._mean_std(outs)
        if t is not None:
            self.clock.commit(t)
        if self._unit_probe is not None:
            self._probe_units(x)
        return out, std

    def _probe_units(self, x: np.ndarray) -> None:
        """Once per stream each: after UNIT_PROBE samples, warn when the accelerometer reads about 1 (g) or 1000
        (milli-g) at rest, or about 0, where the model needs m/s^2 with gravity; after GYRO_PROBE_S seconds, warn when
        the gyro's rotations fit the accelerometer's gravity in deg/s, not rad/s (`data.gyro_scale`). `correct`
        refuses such a file; a stream has no file to refuse. Outside these, nothing is checked."""
        self._unit_probe.append(np.atleast_2d(x).astype(np.float64))
        self._unit_probe_n += len(self._unit_probe[-1])
        rate = self.clock.rate_hz or 200.0
        if self._unit_probe_n < (GYRO_PROBE_S * rate if self._acc_judged else UNIT_PROBE):
            return  # joined only when there are enough (not at every push)
        seen = np.concatenate(self._unit_probe)
        self._unit_probe = [seen]
        if not self._acc_judged:
            self._acc_judged = True
            self._warn_acc_unit(seen, rate)
            if self._warn_gyro_range(seen):  # said already: the gravity test after GYRO_PROBE_S would say it again
                self._unit_probe = None
                return
        if len(seen) >= GYRO_PROBE_S * rate:
            self._unit_probe = None
            verdict = gyro_scale_verdict(seen[:, 3:], seen[:, :3], rate)
            if verdict.wrong_unit:
                warnings.warn(
                    gyro_unit_message(f"over the stream's first {len(seen)} samples", verdict)
                    + " The model needs rad/s: multiply the gyro by pi/180 (0.0174533) before pushing",
                    SanityWarning,
                    stacklevel=4,
                )

    def _warn_gyro_range(self, seen: np.ndarray) -> bool:
        """`correct`'s range check on the stream's first UNIT_PROBE samples: a 99th-percentile rate no motion reaches
        is a gyro in deg/s (a deg/s gyro in slow motion passes here; the gravity test after GYRO_PROBE_S finds it)."""
        p99 = float(np.percentile(np.linalg.norm(seen[:, :3], axis=1), 99))
        if p99 <= GYRO_P99_MAX:
            return False
        warnings.warn(
            f"the gyro's 99th-percentile norm over the stream's first {len(seen)} samples is {p99:.3g} rad/s "
            f"({np.degrees(p99):.0f} deg/s); real motion stays below ~{GYRO_P99_MAX:g} rad/s: it looks like deg/s. "
            "The model needs rad/s: multiply the gyro by pi/180 (0.0174533) before pushing",
            SanityWarning,
            stacklevel=5,
        )
        return True

    def _warn_acc_unit(self, seen: np.ndarray, rate: float) -> None:
        norm = gravity_norm(seen[:, 3:], seen[:, :3], rate)
        guess = norm.unit_guess()
        if guess is not None:
            hint = {"g": "multiply it by 9.81", "mg": "multiply it by 0.00981"}.get(
                guess, "push the raw specific force, gravity included"
            )
            warnings.warn(
                f"the accelerometer's norm is {norm.g:.4g} {norm.where} over the stream's first {len(seen)} samples, "
                f"expected g = 9.81 m/s^2: it looks {'like ' + guess if guess != 'near zero' else 'near zero'}; "
                f"the model needs m/s^2 with gravity: {hint} before pushing",
                SanityWarning,
                stacklevel=5,
            )

    def push_with_spread(self, sample: ArrayLike, t_ns: StampLike = None) -> tuple[np.ndarray, np.ndarray | None]:
        """(corrected gyro (3,), std over the ensemble's members (3,)); std None for a single model or member."""
        return self._run(sample, t_ns, chunk=False)

    def push_chunk_with_spread(self, chunk: ArrayLike, t_ns: StampLike = None) -> tuple[np.ndarray, np.ndarray | None]:
        """(corrected gyro (N, 3), std over the ensemble's members (N, 3)); std None for a single model or member."""
        return self._run(chunk, t_ns, chunk=True)

    # ------------------------------------------------------------------ per sample
    def push(self, sample: ArrayLike, t_ns: StampLike = None) -> np.ndarray:
        """One raw IMU sample (6,) -> corrected gyro (3,) rad/s, float64 (an ensemble: the members' mean).

        t_ns (optional, int nanoseconds): the sample's timestamp; a stamp out of order or after a gap is refused
        (`StreamTimeError`, state unchanged) and a stream at another rate than the model's warns.
        """
        return self._run(sample, t_ns, chunk=False)[0]

    def _push_checked(self, x: np.ndarray) -> np.ndarray:
        """`push` of a sample `_checked` already cast and checked."""
        if self.backend == "torch":
            return self._push_torch(x)
        if x.shape != (6,):
            raise ValueError(f"push expects one (6,) sample (gyro rad/s, acc m/s^2), got shape {x.shape}")
        h = (x - self._mean) * self._inv_std
        if self.n_pushed == 0:
            self._init_state(h)
        for j, ly in enumerate(self.layers):
            L, buf = self._len[j], self._buf[j]
            p = self._pos[j] + 1
            if p == L:
                p = 0
            buf[p] = h
            buf[p + L] = h
            self._pos[j] = p
            taps = buf[p + 1 : p + L + 1 : ly.dilation].ravel()  # k taps, oldest first
            h = self._acts_np[j](self._w_flat[j] @ taps + self._b[j])
        self.n_pushed += 1
        out = self._C @ x[:3] + self._head_w @ h + self._head_b
        return out.astype(np.float64)

    @torch.no_grad()
    def _push_torch(self, sample) -> np.ndarray:
        x = torch.as_tensor(np.asarray(sample), dtype=self.t_dtype)
        if x.shape != (6,):
            raise ValueError(f"push expects one (6,) sample (gyro rad/s, acc m/s^2), got shape {tuple(x.shape)}")
        h = (x - self._t_mean) * self._t_inv_std
        if self.n_pushed == 0:
            self._init_state(h.double().numpy())
        for j, ly in enumerate(self.layers):
            L, buf = self._len[j], self._buf[j]
            p = (self._pos[j] + 1) % L
            buf[p] = h
            buf[p + L] = h
            self._pos[j] = p
            taps = buf[p + 1 : p + L + 1 : ly.dilation].reshape(-1)
            h = self._t_acts[j](torch.addmv(self._t_b[j], self._t_w_flat[j], taps))
        self.n_pushed += 1
        out = self._t_C @ x[:3] + torch.addmv(self._t_head_b, self._t_head_w, h)
        return out.double().numpy()

    # ------------------------------------------------------------------ chunks
    def push_chunk(self, chunk: ArrayLike, t_ns: StampLike = None) -> np.ndarray:
        """(N, 6) raw IMU samples -> (N, 3) corrected gyro, float64; continues the same state.

        Each layer runs as a valid convolution over [its past inputs, the chunk], vectorised over
        the chunk (O(1) per sample, amortised). t_ns: (N,) int timestamps, checked as in `push`.
        """
        return self._run(chunk, t_ns, chunk=True)[0]

    def _push_chunk_checked(self, x: np.ndarray) -> np.ndarray:
        """`push_chunk` of samples `_checked` already cast and checked."""
        if x.ndim != 2 or x.shape[1] != 6:
            raise ValueError(f"push_chunk expects (N, 6) samples, got shape {x.shape}")
        if len(x) == 0:
            return np.zeros((0, 3))
        h = (x - self._mean) * self._inv_std
        if self.n_pushed == 0:
            self._init_state(h[0])
        for j in range(len(self.layers)):
            L = self._len[j]
            past = self._history(j)  # (L-1, C_in), oldest first
            xc = np.concatenate([past, h]) if self.backend == "numpy" else torch.cat([past, torch.from_numpy(h)])
            self._set_history(j, xc[-(L - 1) :])
            h = self._conv_valid(j, xc)
        self.n_pushed += len(x)
        head = h @ self._head_w.T + self._head_b
        return (x[:, :3] @ self._C.T + head).astype(np.float64)

    def _history(self, j: int):
        L, p = self._len[j], self._pos[j]
        return self._buf[j][p + 2 : p + L + 1]  # the L-1 newest rows (oldest first)

    def _set_history(self, j: int, hist) -> None:
        L, buf = self._len[j], self._buf[j]
        buf[: L - 1] = hist
        buf[L : 2 * L - 1] = hist
        self._pos[j] = L - 2  # newest row; the next push writes row L-1

    def _conv_valid(self, j: int, xc) -> np.ndarray:
        ly = self.layers[j]
        if self.backend == "torch":
            with torch.no_grad():
                y = nn.functional.conv1d(xc.T[None], self._t_w[j], self._t_b[j], dilation=ly.dilation)
                return self._t_acts[j](y)[0].T.numpy()
        win = sliding_window_view(xc, ly.span, axis=0)[:, :, :: ly.dilation]  # (N, C_in, k)
        y = np.tensordot(win, ly.weight.astype(self.np_dtype), axes=([1, 2], [1, 2])) + self._b[j]
        return self._acts_np[j](y)
