"""Find where simulation and measurement disagree, name the missing effects, show the gap shrink.

    python -m gyrodenoise.discrepancy --root ../shared/data/euroc \\
        --fit V1_02_medium V2_01_easy V2_03_difficult --holdout V1_03_difficult V2_02_medium \\
        --out outputs/discrepancy_euroc

Every option, its unit and its default: python -m gyrodenoise.discrepancy --help
"""

from __future__ import annotations

# ruff: noqa: E402
# (the imports follow the hand-over below)
if __name__ == "__main__":  # python -m gyrodenoise.discrepancy: a Ctrl-C during the imports below ends in one line
    from gyrodenoise.launch import run_as_main

    run_as_main("discrepancy.__main__")  # imports this module as gyrodenoise.discrepancy.__main__ and runs its main

import argparse
import math
import os
import re
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, NoReturn

from gyrodenoise.atomic import output_path_problem, read_marker, remove_earlier_outputs, staged_outputs
from gyrodenoise.data.checks import RATE_TOL
from gyrodenoise.data.consistency import noting_data_warnings
from gyrodenoise.data.readers import DataFormatError
from gyrodenoise.data.sequence import sequence_folder
from gyrodenoise.discrepancy.bias_instability import NAME as INSTABILITY
from gyrodenoise.discrepancy.compare import MAX_GT_GAP_S, MIN_STRETCH_S, load_fit_contexts
from gyrodenoise.discrepancy.design import NoTrustedBand
from gyrodenoise.discrepancy.gyro_lines import add_lines_to_model, compared_band_hz, gyro_lines
from gyrodenoise.discrepancy.gyro_lines import sentence as lines_sentence
from gyrodenoise.discrepancy.null import DRAWS
from gyrodenoise.discrepancy.rank import MIN_GAIN
from gyrodenoise.discrepancy.report import write_report
from gyrodenoise.discrepancy.report_plots import PLOT_NAMES
from gyrodenoise.discrepancy.sim_model import write_simulator_model
from gyrodenoise.discrepancy.truth_check import check_sequence, followed_bands
from gyrodenoise.discrepancy.truth_rule import sequence_of, with_truth_rule, withhold_unexplained
from gyrodenoise.discrepancy.workflow import run
from gyrodenoise.notices import interrupt_in_one_line
from gyrodenoise.paths import portable_command, portable_path
from gyrodenoise.provenance import code_version_text, machine_description
from gyrodenoise.sim.effects import EFFECTS


def _effects(s: str, vocabulary: tuple[str, ...] = tuple(EFFECTS)) -> list[str]:
    names = [n.strip() for n in s.split(",") if n.strip()]
    bad = [n for n in names if n not in vocabulary]
    if bad:
        raise argparse.ArgumentTypeError(f"unknown effect(s) {bad}; the vocabulary is {', '.join(sorted(vocabulary))}")
    return names


def _candidates(s: str) -> list[str]:
    """The regression vocabulary and the flicker floor, judged after the selection (`bias_instability`)."""
    return _effects(s, (*EFFECTS, INSTABILITY))


EXAMPLE = """example (EuRoC, the run behind the committed reports/discrepancy_euroc, written elsewhere; 322 s, 2 cores):
  python -m gyrodenoise.discrepancy --root ../shared/data/euroc \\
      --fit V1_02_medium V2_01_easy V2_03_difficult --holdout V1_03_difficult V2_02_medium \\
      --network euroc --gyro-noise-density 1.6968e-4 --out outputs/discrepancy_euroc
a first run in ~20 s: docs/discrepancy.md, "Find the effect a simulator misses" (test world, no null draws)
each sequence held out once, verdicts side by side: python -m gyrodenoise.discrepancy.splits --help
"""


def _default_root() -> Path | None:
    data = os.environ.get("GYRODENOISE_DATA")
    return Path(data) / "euroc" if data else None


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m gyrodenoise.discrepancy",
        description=__doc__.split("\n")[0],
        formatter_class=argparse.RawDescriptionHelpFormatter,  # keeps the example's line breaks
        epilog=EXAMPLE,
    )
    vocabulary = ", ".join(sorted(EFFECTS))
    p.add_argument(
        "--root",
        type=Path,
        metavar="DIR",
        default=_default_root(),
        help="folder of ASL sequences (DIR/NAME/mav0/...); default $GYRODENOISE_DATA/euroc, as the other tools "
        + (f"(here {_default_root()})" if _default_root() else "(GYRODENOISE_DATA is not set here: give --root)"),
    )
    p.add_argument(
        "--fit", nargs="+", required=True, metavar="NAME", help="sequences the effects are fitted on; required"
    )
    p.add_argument(
        "--holdout",
        nargs="+",
        required=True,
        metavar="NAME",
        help="sequences the gap is measured on, never fitted (disjoint from --fit); required",
    )
    p.add_argument(
        "--base",
        type=_effects,
        default="bias,white_noise",  # a string default goes through `type` too
        metavar="EFFECTS",
        help="comma-separated effects every model contains (default: %(default)s)",
    )
    p.add_argument(
        "--candidates",
        type=_candidates,
        default=None,
        metavar="EFFECTS",
        help=f"comma-separated effects to try (default: the whole vocabulary: {vocabulary}; and {INSTABILITY}, a "
        "flicker floor judged after the selection against re-simulations)",
    )
    p.add_argument(
        "--gt-file",
        action="append",
        default=[],
        metavar="NAME=PATH",
        help="ground-truth file of sequence NAME, relative to DIR/NAME/mav0; repeatable (default: "
        "state_groundtruth_estimate0/data.csv, else mocap0/data.csv)",
    )
    p.add_argument(
        "--knot-spacing",
        type=float,
        default=0.05,
        metavar="S",
        help="knot spacing of the spline fitted to the ground truth, in seconds (default: %(default)s s)",
    )
    p.add_argument(
        "--bic-threshold",
        type=float,
        default=10.0,
        metavar="X",
        help="BIC decrease (dimensionless) an effect needs to be named (default: %(default)s)",
    )
    p.add_argument(
        "--min-gain",
        type=float,
        default=MIN_GAIN,
        metavar="F",
        help="share (0-1) of the in-band residual power of the held-out sequences an effect must close to be "
        "named (default: %(default)s)",
    )
    p.add_argument(
        "--null-draws",
        type=int,
        default=DRAWS,
        metavar="N",
        help="re-simulations of the fitted base model for the null distribution of every candidate's delta BIC; "
        "an effect is named above its 95th percentile (0: the fixed --bic-threshold alone; default: %(default)s)",
    )
    p.add_argument(
        "--network",
        default=None,
        metavar="MODEL",
        help="also regress the correction of a trained denoiser (shipped name such as euroc, or a .pt/.ckpt "
        "path) on the effect library; one with memory must be trained at the recordings' rate (default: none)",
    )
    p.add_argument(
        "--gyro-noise-density",
        type=noise_density,
        default=None,
        metavar="SIGMA[UNIT]",
        help="the gyro's datasheet white-noise density, in rad/s/sqrt(Hz) unless a unit follows the number: "
        f"{', '.join(NOISE_DENSITY_UNITS)} (EuRoC's ADIS16448: 1.6968e-4, or 0.583deg/sqrt(h)); with it "
        "the report checks per band whether a sequence's ground truth follows the gyro, and effects judged "
        "against a fit sequence's truth that follows it inside the compared band are withheld (default: no check)",
    )
    p.add_argument("--seed", type=int, default=0, help="random seed of the re-simulations (default: %(default)s)")
    p.add_argument(
        "--out",
        type=Path,
        required=True,
        metavar="DIR",
        help="output folder for report.md, report.json and the plots; required",
    )
    return p


# the units datasheets give a gyro's white noise in, and their factor to rad/s/sqrt(Hz)
NOISE_DENSITY_UNITS = {
    "rad/s/sqrt(Hz)": 1.0,
    "deg/s/sqrt(Hz)": math.pi / 180,
    "deg/h/sqrt(Hz)": math.pi / 180 / 3600,
    "deg/sqrt(h)": math.pi / 180 / 60,  # angle random walk: 1 deg/sqrt(h) = (pi/180)/60 rad/s/sqrt(Hz)
}
# rad/s/sqrt(Hz): navigation-grade fibre optics to the noisiest MEMS (0.29 deg/s/sqrt(Hz))
NOISE_DENSITY_RANGE = (1e-6, 5e-3)


def noise_density(text: str) -> float:
    """'1.7e-4', '0.583deg/sqrt(h)' or '0.0097 deg/s/sqrt(Hz)' -> rad/s/sqrt(Hz); refuses what no gyro has."""
    compact = text.replace(" ", "").replace("√", "sqrt")
    number = compact.rstrip("abcdefghijklmnopqrstuvwxyz/()ABCDEFGHIJKLMNOPQRSTUVWXYZ")
    unit = compact[len(number) :] or "rad/s/sqrt(Hz)"
    units = {u.lower().replace("(", "").replace(")", ""): f for u, f in NOISE_DENSITY_UNITS.items()}
    factor = units.get(unit.lower().replace("(", "").replace(")", ""))
    try:
        value = float(number)
    except ValueError:
        value = math.nan
    if factor is None or not value > 0:
        raise argparse.ArgumentTypeError(
            f"{text!r}: give a positive number, optionally followed by one of {', '.join(NOISE_DENSITY_UNITS)}"
        )
    sigma = value * factor
    lo, hi = NOISE_DENSITY_RANGE
    if not lo <= sigma <= hi:
        raise argparse.ArgumentTypeError(
            f"{text!r} is {sigma:.3g} rad/s/sqrt(Hz), outside what gyros have ({lo:g} to {hi:g}): is the unit right? "
            f"(a number without a unit is read in rad/s/sqrt(Hz); units: {', '.join(NOISE_DENSITY_UNITS)})"
        )
    return sigma


def parse_args(
    argv: list[str] | None = None,
    error: Callable[[str], NoReturn] | None = None,
    network_model: tuple[Any, dict] | None = None,
) -> argparse.Namespace:
    """The options, checked; `error`: what says a wrong one and exits (default: this parser's `error`; the splits
    pass their own parser's, so that their errors carry their name and usage). `network_model`: the `--network`
    model already loaded (the splits load it once for all their runs, and say its warnings once)."""
    p = build_parser()
    if error is not None:
        p.error = error  # type: ignore[method-assign]  # argparse's own errors (a bad value, an unknown option) too
    args = p.parse_args(argv)
    overlap = set(args.fit) & set(args.holdout)
    if overlap:
        p.error(f"sequences {sorted(overlap)} are both fitted and held out; the gap must be measured on unseen data")
    for flag, names in (("--fit", args.fit), ("--holdout", args.holdout)):
        if twice := sorted({n for n in names if names.count(n) > 1}):  # counted twice, its evidence would be too
            p.error(f"{flag} names {', '.join(twice)} more than once: give each sequence once")
    gt = {}
    for item in args.gt_file:
        if "=" not in item:
            p.error(f"--gt-file {item!r}: expected NAME=PATH (path relative to <root>/NAME/mav0)")
        k, v = item.split("=", 1)
        if k not in (*args.fit, *args.holdout):  # a misspelt name would fall back to the default truth silently
            p.error(f"--gt-file {item!r}: {k} is not among this run's sequences ({', '.join(args.fit + args.holdout)})")
        gt[k] = v
    args.gt_files = gt
    if not args.knot_spacing > 0:
        p.error(f"--knot-spacing {args.knot_spacing}: must be positive (seconds between the truth spline's knots)")
    if not 0 <= args.min_gain < 1:  # a share: 5 (meant as 5 %?) would let no effect be named, and say nothing
        p.error(f"--min-gain {args.min_gain:g}: a share between 0 and 1 (0.05 for 5 %)")
    if not math.isfinite(args.bic_threshold):  # nan named nothing (every comparison false), without a word
        p.error(f"--bic-threshold {args.bic_threshold}: a finite BIC decrease (default 10)")
    if args.seed < 0:  # numpy's generators take none: it ended in a traceback after the selection
        p.error(f"--seed {args.seed}: a non-negative integer")
    if args.null_draws < 0:
        p.error(f"--null-draws {args.null_draws}: 0 (the fixed --bic-threshold alone) or more re-simulations")
    if args.root is None:
        p.error("--root DIR: the folder of ASL sequences (or set GYRODENOISE_DATA to the folder that holds euroc/)")
    if problem := output_path_problem(args.out, folder=True):  # found before the minutes of work, not after
        p.error(f"--out {args.out}: {problem}")
    # (model, metadata), loaded once, here, for the rate check and the regression (each loaded it again); a model
    # that did not beat the calibrated baseline is said now, not after the minutes of the selection
    args.network_model = network_model if args.network is not None else None
    if args.network is not None and network_model is None:  # a wrong model is said now, not after the minutes
        from gyrodenoise.pretrained import ModelFileError, load_model

        try:
            args.network_model = load_model(args.network)
        except (ModelFileError, FileNotFoundError, ValueError) as e:
            p.error(f"--network: {e}")
    return args


def truth_checks(args: argparse.Namespace, names: list[str]) -> dict:
    """Does each sequence's ground truth follow the gyro? (`truth_check`; flags only with the noise density)"""
    out = {}
    for n in names:
        c = check_sequence(sequence_folder(args.root, n), args.gt_files.get(n), args.gyro_noise_density)
        out[n] = {**c, "ground_truth": portable_path(c["ground_truth"]), "follows_gyro_bands_hz": followed_bands(c)}
    return out


def rate_problem(
    fit: list, holdout: list, network: str | None = None, network_model: tuple[Any, dict] | None = None
) -> str | None:
    """Why these recordings cannot go through one run (None: they can): sampled at rates more than `RATE_TOL` apart
    (the spectra, Allan deviations, noise floors and the simulator's model are read at one rate: the first fit
    sequence's), or the `--network` model (`network` as given, `network_model` as `parse_args` loaded it) has memory
    and was trained at another rate than theirs."""
    rates = {sequence_of(fc): fc.rate_hz for fc in [*fit, *holdout]}
    first = fit[0].rate_hz
    if any(abs(r / first - 1.0) > RATE_TOL for r in rates.values()):
        listed = ", ".join(f"{n} {r:.4g} Hz" for n, r in rates.items())
        return (
            f"--fit and --holdout name recordings sampled at different rates ({listed}): the workflow reads them at "
            "one rate (spectra, Allan deviations, noise floors, the simulator's model). Run the recordings of each "
            "rate on their own, or resample them to one rate"
        )
    if network is None and network_model is None:
        return None
    from gyrodenoise.pretrained import load_model, other_rate_warning

    if network_model is None:  # a caller that did not load it: the check is not skipped
        network_model = load_model(network)

    model, meta = network_model
    if said := other_rate_warning(model, meta, rates):
        return f"--network {network}: {said.rstrip('.')}, or leave out --network"
    return None


OWN_OUTPUTS = ("report.md", "error_model.yaml", *(f"{n}.png" for n in PLOT_NAMES))


@interrupt_in_one_line
def main(argv: list[str] | None = None, network_model: tuple[Any, dict] | None = None) -> int:
    """The command; `network_model`: the `--network` model already loaded (`parse_args`)."""
    args = parse_args(argv, network_model=network_model)
    t0 = time.time()
    if (earlier := read_marker(args.out / "report.json")) is not None:  # replaced when this run has finished
        said = earlier.get("command", "?")
        said = f"note: the outputs of an earlier run in {args.out} ({said}) are replaced when this run has finished"
        print(said, file=sys.stderr)
    code = code_version_text()  # now: a run takes minutes, in which the checkout may move

    left_out: list[dict] = []  # stretches between ground-truth gaps too short to compare

    data_warnings: list[str] = []  # the IMU against its truth (`consistency`): shown now, kept in the report

    def load(names: list[str]) -> list:
        out = []
        for n in names:
            with noting_data_warnings() as found:
                fcs, left = load_fit_contexts(args.root, n, args.gt_files.get(n), args.knot_spacing)
            for w in found:
                print(f"warning: {w}", file=sys.stderr)
            data_warnings.extend(found)
            out += fcs
            left_out.extend(left)
        return out

    try:
        fit, holdout = load(args.fit), load(args.holdout)
    except (FileNotFoundError, DataFormatError) as e:  # a wrong --root, sequence name or file: one line, not a trace
        said = re.sub(r"\+dataset\.gt_files\.(\S+)=", r"--gt-file \1=", str(e))  # this command's option, not training's
        print(f"error: {said}", file=sys.stderr)
        return 2
    if said := rate_problem(fit, holdout, args.network, args.network_model):  # before the minutes of the selection
        print(f"error: {said}", file=sys.stderr)
        return 2

    null_cache: dict = {}  # a second selection on other held-out sequences reuses the null distribution

    def select(hold: list, candidates: list[str] | None) -> tuple[tuple[dict, dict], list[str]]:
        a = args
        out = run(fit, hold, a.base, candidates, a.bic_threshold, a.min_gain, a.seed, a.null_draws, null_cache)
        return out, [e["name"] for e in out[0]["named_effects"]]

    checks = truth_checks(args, [*args.fit, *args.holdout])
    try:
        (report, arrays), rule, withheld = with_truth_rule(select, fit, holdout, checks, args.base, args.candidates)
    except NoTrustedBand as e:
        print(f"error: --knot-spacing {args.knot_spacing:g}: {e}", file=sys.stderr)
        return 2
    withhold_unexplained(report, rule)
    if rule.note():
        report["verdict"] += "; " + rule.note()
        report["truth_followed"] = rule.summary(withheld)
    report["command"] = "python -m gyrodenoise.discrepancy " + portable_command(sys.argv[1:] if argv is None else argv)
    report["settings"]["knot_spacing_s"] = args.knot_spacing
    report["rate_hz"] = fit[0].rate_hz  # the simulator is told which rate the model was measured at
    report["truth_check"] = checks
    report["data_warnings"] = data_warnings
    report["ground_truth_gaps"] = {"max_gap_s": MAX_GT_GAP_S, "min_stretch_s": MIN_STRETCH_S, "left_out": left_out}
    report["gyro_lines_above_band"] = gyro_lines(fit + holdout)  # after the selection: each stretch's band is set
    add_lines_to_model(report, fit, holdout, args.seed)
    if args.network:
        from gyrodenoise.discrepancy.network import network_effects

        report["network"] = network_effects(args.network_model, fit + holdout, args.bic_threshold)
    report["wall_time_s"] = time.time() - t0
    report["machine"] = machine_description()
    report["code"] = code
    report["simulator_model"] = "error_model.yaml"  # the fitted model, for the simulator (`sim_model`)
    # written into a hidden folder and moved into place, report.json last: an interrupted or failed run leaves the
    # earlier run's outputs as they were (an earlier run's figures would otherwise stay beside this run's report)
    clear = lambda: remove_earlier_outputs(args.out, "report.json", OWN_OUTPUTS)  # noqa: E731
    with staged_outputs(args.out, "report.json", clear) as stage:
        write_report(stage, report, arrays)
        write_simulator_model(stage / "error_model.yaml", report)
    out = args.out
    print(f"{report['verdict']}; not identifiable: {', '.join(report['not_identifiable']) or 'none'}")
    if said := lines_sentence(report["gyro_lines_above_band"], compared_band_hz(fit + holdout)):
        print(f"note: {said}")
    flagged = {n: c["follows_gyro_bands_hz"] for n, c in checks.items() if c["follows_gyro_bands_hz"]}
    if flagged:  # names and bands as the report writes them, not a Python dict
        where = "; ".join(f"{n} " + ", ".join(f"{lo:g}-{hi:g} Hz" for lo, hi in b) for n, b in flagged.items())
        print(f"caution: the ground truth follows the gyro in {where}; noise levels fitted there are too low")
    gb, ga = report["gap_before"], report["gap_after"]
    print(
        f"held-out residual RMS {gb['residual_rms_rad_s']:.4g} -> {ga['residual_rms_rad_s']:.4g} rad/s, "
        f"median 10-s drift {gb['drift_10s_median_deg']:.3g} -> {ga['drift_10s_median_deg']:.3g} deg, "
        f"Allan gap {gb['allan_gap_log10']:.3f} -> {ga['allan_gap_log10']:.3f}, "
        f"spectral gap {gb['psd_gap_log10']:.3f} -> {ga['psd_gap_log10']:.3f}"
    )
    print(f"report: {out / 'report.md'}")
    return 0
