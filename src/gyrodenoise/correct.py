"""Correct the gyro of your own IMU recording with a trained model; no ground truth needed.

    python -m gyrodenoise.correct mav0/imu0/data.csv --model euroc -o out/
    gyrodenoise-correct imu.csv --model my_model.pt --columns time,gx,gy,gz,ax,ay,az \\
        --time-unit us --gyro-unit deg/s --acc-unit g --resample -o out/

Input: an ASL IMU file (`t[ns], w[rad/s] x3, a[m/s^2] x3`, the default), an ASL sequence folder, or
any CSV with --columns (7 header names or 1-based numbers, in the order t,wx,wy,wz,ax,ay,az) and
the units of the file. Sanity checks run first (gyrodenoise.data.checks): units, time unit, rate
against the model's training rate, |acc| = g at rest, gaps and duplicated stamps.

Output (in --out-dir, default outputs/correct/<recording>): `imu_corrected.csv`, the corrected gyro with
the accelerometer, in the ASL format (ns, rad/s, m/s^2) that the loaders read (an ensemble model adds 3 columns
`w_std_x,w_std_y,w_std_z [rad s^-1]`: the per-sample spread of its members, the uncertainty of the
corrected gyro; the loaders read the first 7 columns); `orientation.txt`, the open-loop orientation
R_n = R_{n-1} exp(w_n dt_n) in TUM format (`t[s] tx ty tz qx qy qz qw`, translation zero), starting
at identity unless --initial-orientation says otherwise; `correct_summary.json` (beside the CSV), what was done.
"""

from __future__ import annotations

# ruff: noqa: E402
# (the imports follow the hand-over below)
if __name__ == "__main__":  # python -m gyrodenoise.correct: a Ctrl-C during the imports below ends in one line
    from gyrodenoise.launch import run_as_main

    run_as_main("correct")  # imports this module as gyrodenoise.correct (as the console script does), runs main

import argparse
import re
import sys
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from scipy.spatial.transform import Rotation

from gyrodenoise.arrays import as_rows
from gyrodenoise.atomic import output_path_problem, read_marker, write_json, write_text
from gyrodenoise.data.checks import GYRO_ABS_MAX, CheckReport, SanityCheckError, SanityWarning, run_checks
from gyrodenoise.data.imu_csv import (
    ACC_UNITS,
    GYRO_UNITS,
    INT64_MAX,
    TIME_UNITS,
    ImuRecording,
    asl_text,
    beyond_int64_advice,
    check_units,
    read_imu_csv,
    resample,
)
from gyrodenoise.data.readers import DataFormatError
from gyrodenoise.models.build import check_stream_form
from gyrodenoise.models.ensemble import CorrectionModel, predict_with_spread
from gyrodenoise.notices import interrupt_in_one_line, plain_project_warnings
from gyrodenoise.paths import portable_command, portable_path
from gyrodenoise.pretrained import (
    ModelQualityWarning,
    load_model,
    model_quality_warning,
    model_rate,
    resample_rate,
    sensor_model,
)
from gyrodenoise.so3 import integrate_gyro
from gyrodenoise.spread_check import no_reference_note, spread_ratio, spread_warning, worst_window
from gyrodenoise.streaming import StreamingCorrector
from gyrodenoise.trajectory_files import tum_text

ENGINES = ("batch", "streaming")
STREAM_CHUNK = 4096  # samples per push_chunk: bounded memory on long recordings


@dataclass
class Correction:
    rec: ImuRecording  # the samples corrected (after deduplication / resampling)
    gyro: np.ndarray  # (N, 3) corrected, rad/s
    std: np.ndarray | None  # (N, 3) rad/s, spread of an ensemble's members; None for a single model
    R: np.ndarray  # (N, 3, 3) open-loop orientation
    report: CheckReport
    resampled_to_hz: float | None


def _holds_imu_file(folder: Path) -> bool:
    """Whether `folder` is an ASL sequence; False where it cannot be read (a drive's lost+found: on Python 3.11
    is_file() raises PermissionError there, which would replace the message it serves)."""
    try:
        return (folder / "mav0" / "imu0" / "data.csv").is_file()
    except OSError:
        return False


def find_imu_file(path: str | Path) -> Path:
    """A file as is; a folder: its mav0/imu0/data.csv or imu0/data.csv (ASL layout)."""
    p = Path(path)
    if p.is_dir():
        for sub in ("mav0/imu0/data.csv", "imu0/data.csv", "data.csv"):
            if (p / sub).is_file():
                return p / sub
        # a dataset's folder (dataset.root), which holds sequence folders: name them, one recording per command
        held = sorted(d.name for d in p.iterdir() if _holds_imu_file(d))
        shown = ", ".join(held[:8]) + (f" and {len(held) - 8} more" if len(held) > 8 else "")
        hint = f" It holds the sequence folders {shown}: give one of them (one recording per command)." if held else ""
        raise FileNotFoundError(f"{p}: folder without mav0/imu0/data.csv, imu0/data.csv or data.csv.{hint}")
    return p


def default_out_dir(imu_file: Path) -> Path:
    """outputs/correct/<recording>: the ASL sequence folder's name (SEQ/mav0/imu0/data.csv), else the file's stem."""
    parts = imu_file.resolve().parts
    if len(parts) >= 4 and parts[-3:-1] == ("mav0", "imu0"):
        return Path("outputs", "correct", parts[-4])
    if len(parts) >= 3 and parts[-2] == "imu0":
        return Path("outputs", "correct", parts[-3])
    return Path("outputs", "correct", imu_file.stem)


def correct_gyro(
    model: CorrectionModel, imu: np.ndarray, engine: str = "batch"
) -> tuple[np.ndarray, np.ndarray | None]:
    """(N, 6) raw IMU -> ((N, 3) corrected gyro, (N, 3) ensemble std or None), by the batch model or
    the streaming corrector."""
    if engine == "batch":
        gyro, std = predict_with_spread(model, imu)
    elif engine == "streaming":
        sc = StreamingCorrector(model)
        parts = [sc.push_chunk_with_spread(imu[i : i + STREAM_CHUNK]) for i in range(0, len(imu), STREAM_CHUNK)]
        gyro = np.concatenate([g for g, _ in parts])
        std = None if parts[0][1] is None else np.concatenate([s for _, s in parts])
    else:
        raise ValueError(f"engine={engine!r}; choose one of {ENGINES}")
    return gyro, std  # None for a one-member ensemble too: no std columns, as the C example writes none


STD_HEADER = ",w_std_x [rad s^-1],w_std_y [rad s^-1],w_std_z [rad s^-1]"


def corrected_csv_text(t_ns: np.ndarray, gyro: np.ndarray, acc: np.ndarray, std: np.ndarray | None) -> str:
    """The ASL text of the corrected IMU; with an ensemble's std, 3 more columns at the end of each line."""
    text = asl_text(t_ns, gyro, acc)
    if std is None:
        return text
    lines = text.rstrip("\n").split("\n")
    out = [lines[0] + STD_HEADER]
    out += [f"{line},{s[0]:.6g},{s[1]:.6g},{s[2]:.6g}" for line, s in zip(lines[1:], std.tolist(), strict=True)]
    return "\n".join(out) + "\n"


START_REST_DEG_S = 2.0  # a gravity start from a first 0.5 s turning faster than this on average is said to move


def initial_rotation(spec: str, rec: ImuRecording, report: CheckReport | None = None) -> np.ndarray:
    """identity | gravity (roll/pitch from the mean acc of the first 0.5 s, yaw 0) | qx,qy,qz,qw. With `report`, a
    gravity start whose first 0.5 s is not at rest is said there (the motion's acceleration tilts it)."""
    if spec == "identity":
        return np.eye(3)
    if spec == "gravity":
        first = rec.t_ns <= rec.t_ns[0] + 500_000_000
        f = rec.acc[first].mean(0)  # specific force at rest points up in the world (z up)
        turning = float(np.degrees(np.linalg.norm(rec.gyro[first], axis=1).mean()))
        norm = np.linalg.norm(rec.acc[first], axis=1)
        varies = float(norm.std() / np.median(norm))
        if report is not None and (turning > START_REST_DEG_S or varies > 0.03):  # the rest test of the unit check
            report.warn(
                f"{rec.path}: --initial-orientation gravity takes roll and pitch from the first 0.5 s, but the IMU "
                f"moves there (gyro {turning:.1f} deg/s on average, |acc| varies by {100 * varies:.0f} %): "
                "the motion's acceleration tilts that start. Start the recording at rest, or give the start as a "
                "quaternion qx,qy,qz,qw."
            )
        R, _ = Rotation.align_vectors([[0.0, 0.0, 1.0]], [f / np.linalg.norm(f)])
        return R.as_matrix()
    try:
        q = np.array([float(v) for v in spec.split(",")])
    except ValueError:
        q = np.zeros(0)
    if q.shape != (4,) or not np.isclose(np.linalg.norm(q), 1.0, atol=1e-3):
        raise ValueError(
            f"--initial-orientation {spec!r}: give identity, gravity, or a unit quaternion qx,qy,qz,qw (scalar last)"
        )
    return Rotation.from_quat(q).as_matrix()


def correct_recording(
    rec: ImuRecording,
    model: CorrectionModel,
    meta: dict,
    resample_to_model: bool = False,
    drop_duplicates: bool = False,
    force: bool = False,
    engine: str = "batch",
    initial: str = "identity",
) -> Correction:
    rate = model_rate(meta)
    memory = int(getattr(model, "receptive_field", 1)) > 1  # a calibrated model corrects each sample alone
    rec, report, need_resample = run_checks(rec, rate, resample_to_model, drop_duplicates, force, rate_matters=memory)
    target = resample_rate(meta) if need_resample else None
    if target is not None:
        rec = resample(rec, target)
    gyro, std = correct_gyro(model, rec.imu, engine)
    if not np.isfinite(gyro).all() or np.abs(gyro).max(initial=0.0) > GYRO_ABS_MAX:
        # the recording passed its checks: corrections no gyro measures come from the model (damaged weights)
        k = int(np.argmax(~np.isfinite(gyro).all(1) | (np.abs(gyro) > GYRO_ABS_MAX).any(1)))
        raise SanityCheckError(
            f"{meta.get('name', 'the model')}: its corrected gyro at sample {k} is {gyro[k].tolist()} rad/s, beyond "
            f"what any gyro measures ({GYRO_ABS_MAX:g} rad/s) while the recording's is within it: the model file is "
            "damaged or not a gyro model; load it again from its source"
        )
    t = (rec.t_ns - rec.t_ns[0]) * 1e-9
    dt = np.diff(t, prepend=t[0])
    R = integrate_gyro(initial_rotation(initial, rec, report), gyro, dt)
    return Correction(rec, gyro, std, R, report, target)


# the command line's advice in correct_arrays' terms: its checks name the options of gyrodenoise-correct
PYTHON_ADVICE = (
    (r"--(time|gyro|acc)-unit ([A-Za-z/^0-9]+)", r"\1_unit='\2'"),
    (r"--force", "force=True"),
    (r"--resample", "resample_to_model=True"),
    (r"--drop-duplicates", "drop_duplicates=True"),
    (r"\b([Tt])he file is", r"\1he arrays are"),
)


def correct_arrays(
    t: np.ndarray,
    gyro: np.ndarray,
    acc: np.ndarray,
    model: str | Path | CorrectionModel = "euroc",
    *,
    time_unit: str = "s",
    gyro_unit: str = "rad/s",
    acc_unit: str = "m/s^2",
    **kwargs,
) -> Correction:
    """Correct arrays of your own IMU samples, with the sanity checks of `gyrodenoise-correct`.

    t: (N,) stamps in `time_unit` (ns, us, ms, s; integer ns stay exact; float32 stamps rounded by over 1 % of the
    sample period are refused); gyro, acc: (N, 3) in `gyro_unit` /
    `acc_unit` (converted here to rad/s and m/s^2). model: a shipped name, a model file or a run folder, or a loaded
    model (then without its metadata: no rate check, no quality warning). kwargs: those of `correct_recording`
    (resample_to_model, drop_duplicates, force, engine, initial). Returns the `Correction`: corrected gyro (rad/s),
    the ensemble's spread (or None), open-loop orientation R from `initial`, the checks' report. A failed check
    raises SanityCheckError naming the row (counted from 1) and the argument to change.
    """
    t_in, gyro, acc = np.asarray(t), as_rows(gyro, "gyro", 3), as_rows(acc, "acc", 3)
    if t_in.shape != (len(gyro),) or len(acc) != len(gyro):
        raise ValueError(f"t {t_in.shape}, gyro {gyro.shape}, acc {acc.shape}: give one stamp and one row per sample")
    check_units(time_unit, gyro_unit, acc_unit)
    for name, arr in (("t", t_in), ("gyro", gyro), ("acc", acc)):  # named here: the model sees one stacked array
        if np.issubdtype(arr.dtype, np.number) and not np.isfinite(arr).all():
            k = np.argwhere(~np.isfinite(arr))[0]
            where = f"{name}[{', '.join(str(int(i)) for i in k)}]"
            raise ValueError(
                f"{where} is {arr[tuple(k)]} (row {int(k[0]) + 1}, counted from 1; {int((~np.isfinite(arr)).sum())} "
                "value(s) in all): repair or drop those rows first; the network's outputs depend on the last ~2.5 s "
                "of samples, so one bad sample spoils hundreds of outputs"
            )
    largest = float(np.abs(t_in).max()) if t_in.size else 0.0
    if np.issubdtype(t_in.dtype, np.floating) and np.finfo(t_in.dtype).bits < 64 and t_in.size > 1:
        _refuse_coarse_float_stamps(t_in, largest, time_unit)
    if largest * TIME_UNITS[time_unit] > INT64_MAX:  # would wrap around in int64 ns
        advice = beyond_int64_advice(np.diff(t_in.astype(np.float64)), time_unit)
        raise DataFormatError(python_advice(f"t: {largest:.4g} {time_unit} is {advice}."))
    if np.issubdtype(t_in.dtype, np.integer):  # int stamps stay exact (float64 ns of a 2014 epoch: 256-ns steps)
        t_ns = t_in.astype(np.int64) * TIME_UNITS[time_unit]
    else:
        t_ns = np.round(t_in.astype(np.float64) * TIME_UNITS[time_unit]).astype(np.int64)
    rec = ImuRecording(
        t_ns=t_ns,
        gyro=gyro * GYRO_UNITS[gyro_unit],
        acc=acc * ACC_UNITS[acc_unit],
        lines=np.arange(1, len(t_ns) + 1),
        path=Path("<arrays>"),
        columns={
            "t": "t",
            **{f"{k}{c}": f"{name}[:, {i}]" for k, name in (("w", "gyro"), ("a", "acc")) for i, c in enumerate("xyz")},
        },  # fmt: skip
        units={"time": time_unit, "gyro": gyro_unit, "acc": acc_unit},
    )
    loaded, meta = (model, {}) if isinstance(model, torch.nn.Module) else load_model(model, warn=False)
    if msg := model_quality_warning(meta):
        warnings.warn(msg, ModelQualityWarning, stacklevel=2)
    try:
        return correct_recording(rec, loaded, meta, **kwargs)
    except SanityCheckError as e:
        raise SanityCheckError(python_advice(str(e))) from None


FLOAT_STAMP_TOL = 0.01  # float32 stamps rounded by more than this share of the sample period lost their time


def _refuse_coarse_float_stamps(t: np.ndarray, largest: float, unit: str) -> None:
    """ValueError when stamps held in float32 (or float16) are rounded by more than FLOAT_STAMP_TOL of their mean step:
    absolute seconds in float32 come in steps of 128 s; seconds into a long recording jitter the sample period."""
    spacing = float(np.spacing(t.dtype.type(largest)))
    step = abs(float(t[-1]) - float(t[0])) / (len(t) - 1)
    if spacing <= FLOAT_STAMP_TOL * step:
        return
    share = f", {100 * spacing / step:.2g} % of the mean step" if step > 0 else ", more than the steps between them"
    raise ValueError(
        f"t is {t.dtype}: its {np.finfo(t.dtype).nmant + 1}-bit mantissa rounds stamps near {largest:.3g} {unit} to "
        f"{spacing:.3g} {unit}{share}, so the samples' times are lost (time is never float32: integer ns, or float64 "
        "s). Pass t as float64 or as integer ns (time_unit='ns'), taken from the source before it was float32: a "
        "float64 copy of these stamps keeps their rounding"
    )


def python_advice(message: str) -> str:
    """A message of the command line's checks in `correct_arrays`' terms (its arguments for the options)."""
    for option, argument in PYTHON_ADVICE:
        message = re.sub(option, argument, message)
    return message


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(
        prog="gyrodenoise-correct",
        description="Correct the gyro of an IMU recording with a model trained on that IMU (no ground truth needed).",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog=__doc__.split("\n\n", 1)[1],
    )
    ap.add_argument("input", help="IMU CSV file, or an ASL sequence folder (with mav0/imu0/data.csv)")
    ap.add_argument("-m", "--model", default="euroc", help="shipped model name or .pt/.ckpt path (default: euroc)")
    ap.add_argument(
        "-o",
        "--out-dir",
        type=Path,
        help="output folder (default: outputs/correct/NAME, NAME the ASL sequence folder or the file's stem)",
    )
    ap.add_argument("--out-csv", type=Path, help="corrected IMU CSV (default: OUT_DIR/imu_corrected.csv)")
    ap.add_argument("--out-tum", type=Path, help="orientation, TUM format (default: OUT_DIR/orientation.txt)")
    ap.add_argument(
        "--columns",
        default="1,2,3,4,5,6,7",
        help="t,wx,wy,wz,ax,ay,az as header names or 1-based numbers (default: 1,2,3,4,5,6,7, the ASL order)",
    )
    ap.add_argument("--delimiter", help="field separator (default: guessed among , ; tab whitespace)")
    # not given: the unit the header's column names declare ('gx [deg/s]', 't (s)'), else the ASL format's
    ap.add_argument("--time-unit", choices=list(TIME_UNITS), help="(default: the header's, else ns)")
    ap.add_argument("--gyro-unit", choices=list(GYRO_UNITS), help="(default: the header's, else rad/s)")
    ap.add_argument("--acc-unit", choices=list(ACC_UNITS), help="(default: the header's, else m/s^2)")
    ap.add_argument(
        "--resample",
        action="store_true",
        help="resample to the model's training rate when it differs: its sensor's nominal rate (200 Hz for euroc, "
        "not the 200.0026 Hz its clock measured); down: averaged over each new period, against aliasing; up: linear "
        "interpolation",
    )
    ap.add_argument("--drop-duplicates", action="store_true", help="keep the first sample of duplicated stamps")
    ap.add_argument("--force", action="store_true", help="unit checks warn instead of stopping")
    ap.add_argument(
        "--strict",
        action="store_true",
        help="exit 3 (the outputs still written) when a warning says the model does not fit: it did not beat the "
        "calibrated baseline, its ensemble disagrees on this recording far more than on its training data, or the "
        "recording's rate is not the model's (without --resample)",
    )
    ap.add_argument("--engine", choices=ENGINES, default="batch", help="batch model or streaming corrector")
    ap.add_argument(
        "--initial-orientation",
        default="identity",
        help="identity (default), gravity (roll/pitch from the accelerometer), or qx,qy,qz,qw",
    )
    return ap


@interrupt_in_one_line
def main(argv: list[str] | None = None) -> int:
    with plain_project_warnings():  # e.g. a cut last line: one 'warning: ...' line, not Python's two
        return _main(argv)


def _main(argv: list[str] | None) -> int:
    args = build_parser().parse_args(argv)
    try:
        path = find_imu_file(args.input)
        out_dir = args.out_dir or default_out_dir(path)
        out_csv = args.out_csv or out_dir / "imu_corrected.csv"
        out_tum = args.out_tum or out_dir / "orientation.txt"
        for flag, target, folder in (
            ("-o", args.out_dir, True),
            ("--out-csv", out_csv, False),
            ("--out-tum", out_tum, False),
        ):
            # asked before the work: found after it, a wrong path would leave half the outputs
            if target is not None and (problem := output_path_problem(target, folder)):
                hint = " (or -o DIR for a folder)" if not folder and target.is_dir() else ""
                raise ValueError(f"{flag} {target}: {problem}{hint}")
        refuse_colliding_outputs(path, out_csv, out_tum)
        for flag, folder in (("--out-csv", out_csv.parent), ("--out-tum", out_tum.parent)):
            try:  # made now: a folder that cannot be made (read-only, /proc) is found before the work, not after
                folder.mkdir(parents=True, exist_ok=True)
            except OSError as e:
                raise ValueError(f"{flag}: the folder {folder} cannot be made ({e.strerror})") from None
        try:
            model, meta = load_model(args.model, warn=False)  # its warning is listed with the others
        except RuntimeError as e:  # a state dict that does not fit the model's config
            raise ValueError(f"model {args.model!r} cannot be loaded by this version of gyrodenoise: {e}") from None
        if args.engine == "streaming":  # a model without a streaming form is refused before the data is read
            check_stream_form(model)
        rec = read_imu_csv(path, args.columns, args.time_unit, args.gyro_unit, args.acc_unit, args.delimiter)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", SanityWarning)  # printed below from the report
            res = correct_recording(
                rec,
                model,
                meta,
                args.resample,
                args.drop_duplicates,
                args.force,
                args.engine,
                args.initial_orientation,
            )
    except (DataFormatError, FileNotFoundError, ValueError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    ratio = spread_ratio(res.std, meta)
    window = worst_window(res.std, meta, res.resampled_to_hz or res.report.rate_hz)  # the rate of res.std
    model_warnings = [w for w in (model_quality_warning(meta), spread_warning(ratio, str(path), meta, window)) if w]
    if res.std is not None and ratio is None:
        print(f"note: {no_reference_note(meta)}")
    for w in [*model_warnings, *res.report.warnings]:
        print(f"warning: {w}", file=sys.stderr)
    for n in res.report.notes:
        print(f"note: {n}", file=sys.stderr)
    if rec.units_from_header:  # read in the units its header declares: say so, the flags would override them
        said = ", ".join(f"{k} in {rec.units[k]}" for k in rec.units_from_header)
        print(f"note: read {said}, as the header declares (--{rec.units_from_header[0]}-unit ... overrides)")
    summary_file = out_csv.parent / "correct_summary.json"
    if (earlier := read_marker(summary_file)) is not None:  # say so: the earlier outputs (maybe of another model)
        said = f"(model {earlier.get('model', '?')})"
        print(f"note: replacing the outputs of an earlier run in {out_csv.parent} {said}", file=sys.stderr)
    for stale in (summary_file, out_tum, out_csv):  # an interrupted rerun must not leave an earlier run's outputs
        stale.unlink(missing_ok=True)
    write_text(out_csv, corrected_csv_text(res.rec.t_ns, res.gyro, res.rec.acc, res.std))
    write_text(
        out_tum, tum_text(res.rec.t_ns, res.R, "open-loop orientation from the corrected gyro; translation zero")
    )
    delta = np.linalg.norm(res.gyro - res.rec.gyro, axis=1)
    summary = {
        "command": "gyrodenoise-correct " + portable_command(argv if argv is not None else sys.argv[1:]),
        "input": portable_path(path),
        "model": meta["name"],
        "model_rate_hz": model_rate(meta),
        "engine": args.engine,
        "samples": len(res.rec),
        "duration_s": float((res.rec.t_ns[-1] - res.rec.t_ns[0]) * 1e-9),
        "input_units": rec.units,  # as read: given, else the header's, else the ASL format's
        "units_from_header": rec.units_from_header,
        "input_rate_hz": res.report.rate_hz,
        "resampled_to_hz": res.resampled_to_hz,
        "g_measured_m_s2": res.report.g_measured,
        "rest_fraction": res.report.rest_fraction,
        "mean_correction_deg_s": float(np.degrees(delta.mean())),
        "ensemble_members": len(model.members) if res.std is not None else None,
        "mean_std_deg_s": None if res.std is None else float(np.degrees(np.linalg.norm(res.std, axis=1).mean())),
        "spread_ratio_to_training": ratio,  # None: a single model, or an ensemble without a spread reference
        "spread_ratio_worst_window": None if window is None else {"ratio": window[0], "start_s": window[1]},
        "beats_calibrated": meta.get("beats_calibrated"),
        "model_trained_on": trained_on(meta),
        "warnings": model_warnings + res.report.warnings,
        "notes": res.report.notes,
        "outputs": {"imu_csv": portable_path(out_csv), "orientation_tum": portable_path(out_tum)},
    }
    write_json(summary_file, summary)
    print(
        f"corrected {len(res.rec)} samples ({summary['duration_s']:.1f} s at {res.report.rate_hz:.4g} Hz"
        f"{f', resampled to {res.resampled_to_hz:g} Hz' if res.resampled_to_hz else ''}) with {meta['name']}; "
        f"mean correction {summary['mean_correction_deg_s']:.3f} deg/s"
        + (
            f"; ensemble of {summary['ensemble_members']}: mean spread {summary['mean_std_deg_s']:.3f} deg/s (norm "
            f"over the axes; columns w_std_x,y,z, means {'/'.join(f'{v:.3f}' for v in np.degrees(res.std.mean(0)))})"
            if res.std is not None
            else ""
        )
        + f"\n  {out_csv}\n  {out_tum}"
    )
    if summary["model_trained_on"]:
        print(
            f"note: {meta['name']} learned the errors of {summary['model_trained_on']}; it is meant for recordings "
            "of that IMU model (for another IMU, train a model on its own data: docs/own-data.md, "
            "'Train on your own ASL folders')",
            file=sys.stderr,
        )
    misfits = model_warnings + res.report.misfits
    if args.strict and misfits:  # a script can tell a correction the model itself distrusts
        print(f"exit 3 (--strict): {len(misfits)} warning(s) above that the model does not fit", file=sys.stderr)
        return 3
    return 0


def refuse_colliding_outputs(input_path: Path, out_csv: Path, out_tum: Path) -> None:
    """ValueError when an output would replace the input recording, or the other output, or the run's summary."""
    named = {"the input": input_path, "--out-csv": out_csv, "--out-tum": out_tum}
    named["the summary"] = out_csv.parent / "correct_summary.json"
    seen: dict[Path, str] = {}
    for what, p in named.items():
        key = p.resolve()
        if key in seen:
            raise ValueError(f"{what} and {seen[key]} are the same file, {p}: give the outputs other paths")
        seen[key] = what


def trained_on(meta: dict) -> str | None:
    """'the euroc dataset's ADIS16448' from a model's metadata, or None when it does not say (asl_folder's
    placeholder 'unknown' included)."""
    sensor = sensor_model(meta)
    if not sensor:
        return None
    return f"the {meta['dataset']} dataset's {sensor}" if meta.get("dataset") else f"a {sensor}"
