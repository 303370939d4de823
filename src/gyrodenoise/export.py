"""Export a trained correction model to ONNX and to a torch.export program.

The exported graph is the whole correction: raw IMU (B, N, 6) [gyro rad/s, acc m/s^2] in,
corrected gyro (B, N, 3) rad/s out. Input normalisation (the model's mean/std buffers), the causal
left padding and C_hat are inside the graph; the length N (and batch B) are dynamic. An ensemble
(`EnsembleCorrection`) exports to one graph with two outputs: the members' mean `gyro_corrected`
and their per-sample std `gyro_std` (B, N, 3) rad/s.

That graph keeps no state: every call pads its start. `--stateful` exports the streaming step instead
(`gyrodenoise.stateful_graph`): inputs `imu` (B, N, 6), `state` (B, S) and `reset` (B,) bool, outputs the
corrected gyro (and std), and `state_out` to feed back with the next chunk; chunks of any length, one sample
included, then give the batch model's outputs on the whole stream.

    python -m gyrodenoise.export euroc --onnx euroc.onnx [--pt2 euroc.pt2] [--stateful]
    python -m gyrodenoise.export euroc --c OUT_DIR       # plain C99 streaming step (`gyrodenoise.c_export`)

ONNX uses the torch.export-based exporter (`dynamo=True`, torch's default since 2.9), which needs
`onnx` and `onnxscript` (pip install "gyrodenoise[export]").
"""

from __future__ import annotations

# ruff: noqa: E402
# (the imports follow the hand-over below)
if __name__ == "__main__":  # python -m gyrodenoise.export: a Ctrl-C during the imports below ends in one line
    from gyrodenoise.launch import run_as_main

    run_as_main("export")  # imports this module as gyrodenoise.export and runs its main

import argparse
import copy
import importlib.metadata
import os
import sys
import tempfile
import warnings
from pathlib import Path

import torch
from torch import nn

from gyrodenoise import c_export
from gyrodenoise.atomic import atomic_path, output_path_problem
from gyrodenoise.models.build import not_built_in
from gyrodenoise.models.ensemble import CorrectionModel, EnsembleCorrection, has_spread
from gyrodenoise.notices import interrupt_in_one_line, plain_project_warnings, quiet_library_notices
from gyrodenoise.pretrained import load_model, not_better_warning, sensor_model
from gyrodenoise.spread_check import SPREAD_RATIO_LIMIT
from gyrodenoise.stateful_graph import StatefulCorrection

INPUT_NAME, OUTPUT_NAME, STD_NAME = "imu", "gyro_corrected", "gyro_std"
STATE_NAME, RESET_NAME, STATE_OUT_NAME = "state", "reset", "state_out"
OPSET = 18


class ExportWrapper(nn.Module):
    """A plain forward(imu) -> corrected gyro (an ensemble: (mean, std)), in eval mode, float32, on the CPU."""

    def __init__(self, model: CorrectionModel) -> None:
        super().__init__()
        self.model = copy.deepcopy(model).cpu().float()  # the caller's model stays as it was
        self.is_ensemble = has_spread(model)  # a one-member ensemble: its member's output, no std
        self.eval()

    def forward(self, imu: torch.Tensor) -> torch.Tensor | tuple[torch.Tensor, torch.Tensor]:
        if self.is_ensemble:
            return self.model.forward_with_spread(imu)
        return self.model(imu)


PARITY_TOL_RAD_S = 1e-4  # a graph that differs from the model by more is refused (float32 rounding: ~1e-6)


def output_names(model: CorrectionModel) -> list[str]:
    return [OUTPUT_NAME, STD_NAME] if has_spread(model) else [OUTPUT_NAME]


def _example(model: CorrectionModel, n: int = 0) -> torch.Tensor:
    # longer than the receptive field, so tracing sees no special case of short inputs
    n = n or 2 * int(getattr(model, "receptive_field", 1)) + 7
    return torch.randn(2, n, 6) + torch.tensor([0.0, 0.0, 0.0, 0.0, 0.0, 9.81])


def _dynamic_shapes() -> dict:
    return {"imu": {0: torch.export.Dim("batch", min=1), 1: torch.export.Dim("length", min=1)}}


def _graph(model: CorrectionModel, stateful: bool) -> tuple[nn.Module, tuple, dict, tuple[list[str], list[str]]]:
    """The module to export, example inputs, their dynamic shapes, and the input and output names."""
    if not stateful:
        wrapper = ExportWrapper(model).requires_grad_(False)  # an exported program that records no autograd graph
        return wrapper, (_example(model),), _dynamic_shapes(), ([INPUT_NAME], output_names(model))
    # without requires_grad: a loaded .pt2 called outside no_grad would chain state_out's autograd graph across
    # every call and grow without bound (~16 MB/s at 200 Hz for one network)
    step = StatefulCorrection(model).requires_grad_(False)
    if step.state_size == 0:
        raise ValueError("this model keeps no state (a calibrated model): export it without --stateful")
    batch = torch.export.Dim("batch", min=1)  # shared by the three inputs
    imu = _example(step)
    args = (imu, torch.randn(len(imu), step.state_size), torch.tensor([True, False]))
    shapes = {"imu": {0: batch, 1: torch.export.Dim("length", min=1)}, "state": {0: batch}, "reset": {0: batch}}
    return step, args, shapes, ([INPUT_NAME, STATE_NAME, RESET_NAME], [*output_names(model), STATE_OUT_NAME])


def export_program(model: CorrectionModel, stateful: bool = False) -> torch.export.ExportedProgram:
    """torch.export program with dynamic batch and length (`stateful`: the streaming step, as `export_onnx`)."""
    module, args, shapes, _ = _graph(model, stateful)
    with torch.no_grad():
        return torch.export.export(module, args, dynamic_shapes=shapes)


def export_pt2(model: CorrectionModel, path: str | Path, stateful: bool = False) -> Path:
    """Save the torch.export program (load with torch.export.load(path).module())."""
    path = Path(path)
    program = export_program(model, stateful)
    with atomic_path(path, ".pt2") as tmp:
        torch.export.save(program, tmp)
    return path


def onnx_metadata(model: CorrectionModel, meta: dict | None = None, stateful: bool = False) -> dict[str, str]:
    """What a user of the .onnx file needs and the graph does not say: units, channel order, rate, origin."""
    meta = meta or {}
    out = {
        "gyrodenoise.input": f"{INPUT_NAME} (batch, samples, 6): gyro x, y, z [rad/s], accelerometer x, y, z [m/s^2], "
        "IMU body frame, consecutive samples at the training rate, oldest first",
        "gyrodenoise.outputs": ", ".join(output_names(model)) + " (batch, samples, 3) [rad/s]",
    }
    rf = int(getattr(model, "receptive_field", 1))
    out["gyrodenoise.receptive_field_samples"] = str(rf)
    if stateful:
        size = StatefulCorrection(model).state_size
        out["gyrodenoise.inputs"] = (
            f"{INPUT_NAME} (batch, samples >= 1, 6); {STATE_NAME} (batch, {size}) float32: the {STATE_OUT_NAME} of "
            f"the stream's previous call; {RESET_NAME} (batch,) bool: true on a stream's first call ({STATE_NAME} is "
            "then not read)"
        )
        out["gyrodenoise.outputs"] = ", ".join(output_names(model)) + f" (batch, samples, 3) [rad/s], {STATE_OUT_NAME}"
        out["gyrodenoise.start_up"] = (
            f"a stream starts as if preceded by {rf - 1} copies of its first sample (the first ~{rf} samples are less "
            f"accurate); after that, calls of any length that pass {STATE_OUT_NAME} back as {STATE_NAME} give the "
            "outputs of one call on the whole stream. The graph does not check its input: a NaN/inf or impossible "
            f"sample enters the state and spoils the next {rf} outputs, so check samples before the call "
            "(StreamingCorrector refuses them). A state belongs to this file's graph: another model's state of the "
            "same size is accepted and spoils a receptive field of outputs"
        )
    elif own := not_built_in(model):  # a user's network: its start-up and memory are its own
        out["gyrodenoise.start_up"] = (
            f"{own} is a user's network: how it starts a call is its own code's, and its receptive_field says its "
            f"outputs depend on the {rf - 1} samples before them. Back-to-back short calls are not a stream: keep a "
            f"window of >= {rf} samples (one call per sample); --stateful and StreamingCorrector take built-in models "
            "only"
        )
    else:
        out["gyrodenoise.start_up"] = (
            f"each call pads its start with {rf - 1} copies of its first sample: output n is exact once the call "
            f"holds the {rf - 1} samples before n. Back-to-back short calls are not a stream: keep a window of >= "
            f"{rf} samples (one call per sample), export with --stateful (state passed between calls), or stream "
            "with gyrodenoise.streaming.StreamingCorrector"
        )
    out["gyrodenoise.accelerometer"] = (
        "specific force, gravity included (about +9.81 m/s^2 up at rest), not gravity-free"
    )
    out["gyrodenoise.normalization"] = "inside the graph: feed raw SI values"
    if isinstance(model, EnsembleCorrection):
        out["gyrodenoise.ensemble_members"] = str(len(model.members))
    if has_spread(model):
        out["gyrodenoise.gyro_std"] = (
            f"per-sample std of the members' corrected gyro (ddof 1) x spread_scale {float(model.spread_scale):g}; "
            "it ranks the error but underestimates it (see the model card)"
        )
        if ref := (meta.get("spread_reference") or {}).get("reference_rad_s"):
            out["gyrodenoise.spread_check"] = (
                f"the median over a recording of ||gyro_std|| / spread_scale above {SPREAD_RATIO_LIMIT:g} x "
                f"{float(ref):.6g} rad/s (the largest median on the training recordings): the recording is unlike the "
                "training data (another IMU, units or mounting) and the correction is not to be trusted"
            )
    if meta.get("rate_hz"):
        out["gyrodenoise.rate_hz"] = f"{float(meta['rate_hz']):g}"
    sensor = sensor_model(meta)
    if sensor:
        out["gyrodenoise.sensor"] = f"{sensor}: learned the errors of this IMU model; another IMU needs its own model"
    for key in ("name", "dataset", "beats_calibrated"):
        if meta.get(key) is not None:
            out[f"gyrodenoise.{key}"] = str(meta[key])
    if warning := not_better_warning(meta):  # also an ensemble none of whose members did (beats_calibrated None)
        out["gyrodenoise.quality_warning"] = warning
    out["gyrodenoise.exported_by"] = f"gyrodenoise {importlib.metadata.version('gyrodenoise')}"
    return out


def export_onnx(
    model: CorrectionModel, path: str | Path, opset: int = OPSET, meta: dict | None = None, stateful: bool = False
) -> Path:
    """Write a self-contained ONNX file (weights inside) with dynamic batch and length; `meta` (the model file's
    metadata) adds the training rate and origin to the file's metadata_props (`onnx_metadata`). `stateful`: the
    streaming step (inputs imu, state, reset; outputs ..., state_out), see `gyrodenoise.stateful_graph`."""
    for mod in ("onnx", "onnxscript"):
        try:
            __import__(mod)
        except ImportError:
            raise ImportError(f"ONNX export needs the '{mod}' package: pip install 'gyrodenoise[export]'") from None
    path = Path(path)
    wrapper, args, shapes, names = _graph(model, stateful)
    with torch.no_grad(), warnings.catch_warnings():
        # the stateful graph's inputs share one batch dimension on purpose; the exporter warns it keeps one name
        warnings.filterwarnings("ignore", message=r"\W*The axis name: .* will not be used, since it shares")
        program = torch.onnx.export(
            wrapper,
            args,
            dynamo=True,
            input_names=names[0],
            output_names=names[1],
            dynamic_shapes=shapes,
            opset_version=opset,
            external_data=False,
            verbose=False,
        )
    written = program.model.opset_imports.get("", opset)
    if written != opset:  # the exporter falls back to its own opset when it cannot convert: say so
        import onnx

        newest = onnx.defs.onnx_opset_version()  # above it the converter refuses (--opset 99 was told "or higher")
        raise ValueError(
            f"--opset {opset}: the exporter could not convert the graph to ONNX opset {opset} (it can write opset "
            f"{written}), so nothing was written; give --opset from {min(written, newest)} to {newest}, the "
            f"installed onnx's newest (default {OPSET})"
        )
    program.model.metadata_props.update(onnx_metadata(model, meta, stateful))
    with atomic_path(path, ".onnx") as tmp:
        program.save(str(tmp), external_data=False)
    return path


@interrupt_in_one_line
def main(argv: list[str] | None = None) -> int:
    quiet_library_notices()
    ap = argparse.ArgumentParser(
        prog="python -m gyrodenoise.export",
        description="Export a gyro correction model (normalisation and C_hat included) to ONNX / torch.export, or its "
        "streaming step to plain C99 (--c). "
        "Input 'imu' (batch, samples, 6): gyro x, y, z [rad/s] and accelerometer x, y, z [m/s^2] at the model's "
        "training rate; output 'gyro_corrected' (and an ensemble's 'gyro_std') (batch, samples, 3) [rad/s]. "
        "The .onnx file's metadata_props record these and the training rate.",
    )
    ap.add_argument("model", help="shipped model name (e.g. euroc) or path of a .pt model / .ckpt checkpoint")
    ap.add_argument("--onnx", type=Path, help="output .onnx file (dynamic batch and length; the name ends in .onnx)")
    ap.add_argument("--pt2", type=Path, help="output torch.export program (the name ends in .pt2)")
    ap.add_argument("--opset", type=int, default=OPSET, help=f"ONNX opset of the graph (default {OPSET})")
    ap.add_argument(
        "--stateful",
        action="store_true",
        help="export the streaming step (inputs imu, state, reset; outputs ..., state_out): feed state_out back "
        "with the next chunk of any length and the outputs equal one call on the whole stream",
    )
    ap.add_argument(
        "--c",
        type=Path,
        metavar="OUT_DIR",
        help=f"write the streaming step as plain C99 ({c_export.HEADER}, {c_export.SOURCE}, {c_export.EXAMPLE}): no "
        "runtime, no allocation, <math.h>, <string.h> and <stdint.h> only",
    )
    ap.add_argument(
        "--c-prefix",
        default=c_export.DEFAULT_PREFIX,
        metavar="NAME",
        help="with --c: the prefix of the C names (default gd: gd_step, gd_step_t, gd_reset, gd_state, GD_*); another "
        "prefix per model lets two exported models link into one program",
    )
    ap.add_argument(
        "--no-check",
        action="store_true",
        help="skip the parity checks (onnxruntime; for --c, compiling the C code and running it)",
    )
    args = ap.parse_args(argv)
    if not (args.onnx or args.pt2 or args.c):
        ap.error("give at least one of --onnx PATH, --pt2 PATH, --c OUT_DIR")
    for flag, target, folder in (("--onnx", args.onnx, False), ("--pt2", args.pt2, False), ("--c", args.c, True)):
        # asked before the work: otherwise a wrong path is found only when the results are written, with a raw error
        if target is not None and (problem := output_path_problem(target, folder)):
            if not folder and target.is_dir():
                problem += f", e.g. {target / ('model' + flag.replace('--', '.'))}"
            print(f"error: {flag} {target}: cannot write: {problem}", file=sys.stderr)  # as the export's own errors
            return 2
        suffix = flag.replace("--", ".")
        if folder or target is None or target.suffix.lower() == suffix:
            continue
        if target.is_file():  # an existing other file is probably a typo: it is not replaced
            print(
                f"error: {flag} {target}: this file exists and is not a {suffix} file, so it was left as it was: "
                f"give a {suffix} path, or remove the file first",
                file=sys.stderr,
            )
            return 2
        # a new file of another name (--onnx x.txt, or no suffix) was written without a word: the tools that open
        # these files go by the suffix
        print(
            f"error: {flag} {target}: not a {suffix} path, so nothing was written: give a path ending in {suffix}, "
            f"e.g. {target.with_suffix(suffix)}",
            file=sys.stderr,
        )
        return 2
    model = None
    try:
        with plain_project_warnings():  # a model-quality warning as one line, like correct and evaluate
            model, meta = load_model(args.model)
        if args.pt2:
            print(f"wrote {export_pt2(model, args.pt2, args.stateful)}")
        if args.onnx:
            export_onnx(model, args.onnx, args.opset, meta, args.stateful)
            msg = f"wrote {args.onnx}"
            if not args.no_check:
                parity = onnx_stream_parity if args.stateful else onnx_parity
                err = parity(model, args.onnx)
                how = "in chunks of 1 to 700 samples, " if args.stateful else ""
                msg += (
                    f" (onnxruntime {how}vs PyTorch on one random input sequence: max |diff| {err:.2e} rad/s over "
                    f"{', '.join(output_names(model))})"
                )
                if not err <= PARITY_TOL_RAD_S:  # NaN included
                    Path(args.onnx).unlink(missing_ok=True)
                    raise ValueError(
                        f"{args.onnx}: the exported graph does not reproduce the model (max |diff| {err:.2e} rad/s > "
                        f"{PARITY_TOL_RAD_S:g}; float32 rounding gives ~1e-6), so it was removed. A model whose "
                        "forward the exporter traces differently (data-dependent branches, a custom class), or a "
                        "stateful export of a model it cannot step, gives this; --no-check keeps such a file"
                    )
            print(msg)
        if args.c:
            print(write_c(model, args.c, meta, check=not args.no_check, prefix=args.c_prefix))
    except (ImportError, FileNotFoundError, ValueError) as e:  # a missing extra, a model that is not there
        print(f"error: {e}", file=sys.stderr)
        return 2
    except RuntimeError as e:  # torch.export's own refusal: for a user's network, say it in one line
        if model is None or not_built_in(model) is None:
            raise
        first = next((ln.strip() for ln in str(e).splitlines() if ln.strip()), type(e).__name__)
        print(
            f"error: {not_built_in(model)} could not be exported with a dynamic length ({type(e).__name__}: {first}). "
            "A network whose graph depends on the sequence length while tracing (a Python loop over the samples, a "
            "recurrent layer unrolled) exports only at the traced length; export the built-in network, or rewrite "
            "the loop as tensor operations",
            file=sys.stderr,
        )
        return 2
    return 0


def write_c(
    model: CorrectionModel, out_dir: Path, meta: dict, check: bool = True, prefix: str = c_export.DEFAULT_PREFIX
) -> str:
    """Write the C export; with `check`, compile it and compare it with the streaming corrector first, in a folder
    beside `out_dir`: files that do not compile or differ by more than c_export.PARITY_TOL_RAD_S (ValueError), or an
    interrupted check, leave `out_dir` as it was (an earlier export in it included). Returns what to print."""
    out_dir = Path(out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise ValueError(f"--c {out_dir} is a file: give a folder to write the C files into")
    if not check:
        return f"wrote {', '.join(str(p) for p in c_export.export_c(model, out_dir, meta, prefix))}"
    try:
        out_dir.parent.mkdir(parents=True, exist_ok=True)
        staging = tempfile.TemporaryDirectory(dir=out_dir.parent, prefix=f".{out_dir.name}.")
    except OSError as e:
        raise ValueError(f"--c {out_dir}: cannot write the C files there ({e.strerror or e})") from None
    with staging as tmp:
        staged = c_export.export_c(model, tmp, meta, prefix)
        try:
            note = _checked_c(model, Path(tmp), out_dir)
        except _NotCheckable as e:  # built for another machine: the files may be right for it, so they are written
            _move_into(staged, out_dir)
            raise ValueError(f"the C files were written but not checked: {e}") from None
        paths = _move_into(staged, out_dir)
    return f"wrote {', '.join(str(p) for p in paths)}{note}"


class _NotCheckable(Exception):
    """The compiler builds for another machine: the example cannot run here."""


def _move_into(staged: list[Path], out_dir: Path) -> list[Path]:
    out_dir.mkdir(parents=True, exist_ok=True)
    moved = [out_dir / p.name for p in staged]
    for src, dst in zip(staged, moved, strict=True):
        os.replace(src, dst)
    return moved


def _checked_c(model: CorrectionModel, staged_dir: Path, out_dir: Path) -> str:
    """Compile the staged files and compare them with the model: what to add to the 'wrote' line, or ValueError."""
    if (cc := c_export.find_c_compiler()) is None:
        return " (not compiled nor checked: no C compiler found: cc, gcc, clang or $CC)"
    note = (
        f" ($CC={wanted} is not on the PATH: checked with {cc})"
        if (wanted := os.environ.get("CC")) and cc != wanted
        else ""
    )
    try:
        err = c_export.c_parity(model, staged_dir, compiler=cc)
    except RuntimeError as e:  # the generated code fails to compile or to run: say the compiler's first error
        lines = str(e).splitlines()
        first = next((ln for ln in lines if "error" in ln), lines[-1]).strip()
        if "cannot run here" in first:
            raise _NotCheckable(first) from None
        raise ValueError(
            f"the C files do not compile or run with {cc}, so they were not written to {out_dir} (--no-check "
            f"writes them): {first}"
        ) from None
    worst = max(err.values())
    if not worst <= c_export.PARITY_TOL_RAD_S:  # NaN included
        raise ValueError(
            f"{out_dir}: the C code does not reproduce the model (max |diff| {worst:.2e} rad/s > "
            f"{c_export.PARITY_TOL_RAD_S:g}), so its files were not written; --no-check writes them"
        )
    what = ", ".join(k.replace("gyro_batch", "gyro vs the batch model") for k in err)
    return note + (
        f" ({cc} -O2 vs StreamingCorrector and the batch model on 1500 random samples: max |diff| {worst:.2e} rad/s "
        f"over {what})"
    )


def onnx_parity(model: CorrectionModel, path: str | Path, n: int = 1500) -> float:
    """Max |onnxruntime - PyTorch| over all outputs, on random input of a length the export did not see."""
    import numpy as np

    try:
        import onnxruntime as ort
    except ImportError:
        raise ImportError("the parity check needs onnxruntime: pip install 'gyrodenoise[export]'") from None
    x = _example(model, n)[:1]
    sess = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    ys = sess.run(output_names(model), {INPUT_NAME: x.numpy()})
    with torch.no_grad():
        ref = ExportWrapper(model)(x)
    refs = ref if isinstance(ref, tuple) else (ref,)
    return max(float(np.abs(y - r.numpy()).max()) for y, r in zip(ys, refs, strict=True))


def onnx_stream_parity(model: CorrectionModel, path: str | Path, n: int = 1500) -> float:
    """Max |onnxruntime - PyTorch| of a stateful export fed in chunks (1 to 700 samples, state passed back), against
    the model on the whole sequence."""
    import numpy as np

    try:
        import onnxruntime as ort
    except ImportError:
        raise ImportError("the parity check needs onnxruntime: pip install 'gyrodenoise[export]'") from None

    x = _example(model, n)[:1]
    sess = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    names = output_names(model)
    state = np.zeros((1, StatefulCorrection(model).state_size), np.float32)
    outs: list[list[np.ndarray]] = [[] for _ in names]
    start = 0
    for size in (1, 1, 5, 300, 700, 2, n):
        chunk = x[:, start : start + size].numpy()
        if chunk.shape[1] == 0:
            break
        *ys, state = sess.run(
            [*names, STATE_OUT_NAME], {INPUT_NAME: chunk, STATE_NAME: state, RESET_NAME: np.array([start == 0])}
        )
        for o, y in zip(outs, ys, strict=True):
            o.append(y)
        start += size
    with torch.no_grad():
        ref = ExportWrapper(model)(x)
    refs = ref if isinstance(ref, tuple) else (ref,)
    return max(float(np.abs(np.concatenate(o, 1) - r.numpy()).max()) for o, r in zip(outs, refs, strict=True))
