"""Hydra entry point: compare attitude methods on the test sequences (Table 1, Figs. 5-8 of the paper).

    python -m gyrodenoise.evaluate dataset=euroc                     # shipped models
    python -m gyrodenoise.evaluate dataset=euroc weights.proposed=outputs/.../model.pt weights.calibrated=...
    python -m gyrodenoise.evaluate dataset=tumvi split=val weights.proposed=tumvi-denoiser  # validation parts

Methods: raw IMU (integrated gyro), zero motion (initial orientation held), calibrated IMU (the
12-parameter baseline), proposed (the denoiser, or an ensemble of them). Every estimate is aligned
on ground truth at the first instant with ground truth; a part (e.g. split=val's [50s:]) is scored as a stream that
starts there: the network gets no IMU history from before it (its first ~2.5 s see copies of the first sample, as
in training's validation; room1's denoiser: 0.926 deg, 0.897 with the history: benchmarks/network_history.py).
Other methods' orientation estimates join the table as columns: `+estimates.NAME=FOLDER` (FOLDER/<sequence>.txt)
or `'+estimates.NAME=PATH/*.txt'` (* = the sequence's name), TUM trajectories on the IMU's clock
(gyrodenoise.external_estimates).
Outputs in `out_dir`: table.md / table.csv (AOE 3D/yaw per sequence and average),
roe.md / roe.csv (ROE median and quartiles at each distance), results.json, figures/ and
trajectories/<sequence>/<method>.txt (V1_01 against its original ground truth: V1_01_easy__original_GT/;
`trajectories=false`: none; TUM format, readable by evo and
rpg_trajectory_evaluation; stamps exact to the ns;
groundtruth.txt holds positions and only the samples with ground truth, the estimates orientation only, translation
zero: score them on orientation, e.g. `evo_ape tum groundtruth.txt proposed.txt --pose_relation angle_deg`).
They are written into a hidden folder in `out_dir` and moved into place when the run has finished (results.json
last), replacing an earlier evaluation's only then: a failed run leaves none of its own, and what was there stays.
An ensemble as the proposed model adds its uncertainty: a +-2 sigma band in the correction figures,
and in results.json / figures/uncertainty_calibration.png the calibration of its spread against the
actual 1-s increment errors (gyrodenoise.uncertainty). A model whose metadata says it did not beat
the calibrated baseline on validation gets a warning (gyrodenoise.pretrained.ModelQualityWarning), and so does
a model scored on data it was trained on (e.g. the shipped `tumvi`, fitted on the TUM-VI rooms whole, on split=val).
"""

from __future__ import annotations

# ruff: noqa: E402
# (the imports follow the hand-over below)
if __name__ == "__main__":  # python -m gyrodenoise.evaluate: a Ctrl-C during the imports below ends in one line
    from gyrodenoise.launch import run_as_main

    run_as_main("evaluate")  # imports this module as gyrodenoise.evaluate (as the console script does), runs main

import math
import sys
import time
import warnings
from collections.abc import Callable
from pathlib import Path

import hydra
import numpy as np
from omegaconf import DictConfig, ListConfig, OmegaConf, open_dict

from gyrodenoise import plots, uncertainty
from gyrodenoise.atomic import remove_earlier_outputs, staged_outputs, write_json, write_text
from gyrodenoise.cli_errors import ConfigError, hydra_key_hints, torch_threads, user_errors
from gyrodenoise.config import with_output_dir
from gyrodenoise.data.cache import load_sequence
from gyrodenoise.data.consistency import DataConsistencyWarning, noting_data_warnings
from gyrodenoise.data.sequence import Sequence
from gyrodenoise.external_estimates import (
    check_files,
    check_names,
    coverage_note,
    frame_problems,
    load_external,
    nan_outside,
)
from gyrodenoise.job_log import console_to_job_log, job_log_path
from gyrodenoise.metrics import AOE_DEFINITION, ROE_STRIDE, aoe, orientation_errors, roe, summarize
from gyrodenoise.models.ensemble import CorrectionModel, predict_with_spread
from gyrodenoise.paths import portable_path, portable_tree, recorded_command
from gyrodenoise.pretrained import (
    ModelQualityWarning,
    available_models,
    is_shipped,
    load_model,
    model_quality_warning,
    other_imu_warning,
    other_rate_warning,
    training_overlap_warning,
)
from gyrodenoise.provenance import code_version, file_sha256, library_versions, machine_description
from gyrodenoise.so3 import integrate_gyro
from gyrodenoise.spread_check import spread_ratio, spread_warning, worst_window
from gyrodenoise.tables import csv_text, markdown_table
from gyrodenoise.trajectory_files import tum_text

METHODS = ("raw IMU", "zero motion", "calibrated IMU", "proposed")
ROE_DEFINITION = (
    "ROE in degrees: the angle of dR_gt^T dR_est between a start sample (every {stride}th) and the first sample "
    "{d} m of ground-truth path later (positions interpolated linearly across gaps), pooled over the averaged "
    "sequences; pairs with an end inside a ground-truth gap are left out."
)


def gyro_method(model: CorrectionModel | None) -> Callable[[Sequence], np.ndarray | None]:
    """Corrected gyro of a sequence (an ensemble: the members' mean): raw IMU when `model` is None."""

    def run(seq: Sequence) -> np.ndarray:
        return seq.gyro if model is None else predict_with_spread(model, seq.imu)[0]

    return run


def load_checked(name_or_path: str) -> tuple[CorrectionModel, dict, str | None]:
    """load_model, and warn when the model's metadata says it did not beat the calibrated baseline."""
    model, meta = load_model(name_or_path, warn=False)
    msg = model_quality_warning(meta)
    if msg:
        warnings.warn(msg, ModelQualityWarning, stacklevel=2)
    return model, meta, msg


def estimate(seq: Sequence, gyro: np.ndarray | None) -> np.ndarray:
    """Open-loop attitude aligned at the first instant; gyro None means zero motion."""
    if gyro is None:
        return np.repeat(seq.rot[:1], len(seq), axis=0)
    return integrate_gyro(seq.rot[0], gyro, seq.dt)


def model_label(name: str) -> str:
    """A table header's name for a model: a shipped name as it is, a file as `<its folder>/<file>` (a training
    run's model.pt: the run's time stamp), not the whole path (the table's notes give it)."""
    path = Path(name)
    if path.suffix not in (".pt", ".ckpt") and len(path.parts) < 2:
        return name
    return f"{path.parent.name}/{path.name}" if path.parent.name else path.name


def write_trajectories(folder: Path, seq: Sequence, estimates: dict[str, np.ndarray]) -> None:
    """groundtruth.txt (positions too, only the samples with ground truth: an occlusion's SLERP is not a measurement)
    and one orientation-only file per method, all on the IMU's stamps."""
    t_ns = seq.t0_ns + np.round(seq.t * 1e9).astype(np.int64)
    m = seq.gt_mask
    n_out = int((~m).sum())
    gaps = f"; {n_out} samples inside ground-truth gaps left out" if n_out else ""
    write_text(folder / "groundtruth.txt", tum_text(t_ns[m], seq.rot[m], f"ground truth{gaps}", seq.pos[m]))
    for method, R in estimates.items():
        write_text(
            folder / f"{slug(method)}.txt", tum_text(t_ns, R, f"{method}: open-loop orientation; translation zero")
        )


def slug(name: str) -> str:
    return "".join(c if c.isalnum() or c in "-_" else "_" for c in name).strip("_")


def evaluate_sequence(seq: Sequence, gyros: dict[str, np.ndarray | None], distances: list[float]) -> dict:
    out = {"estimates": {}, "aoe": {}, "roe": {}}
    for name, gyro in gyros.items():
        R = estimate(seq, gyro)
        out["estimates"][name] = R
        out["aoe"][name] = aoe(seq.rot, R, seq.gt_mask)
        out["roe"][name] = {d: roe(seq.rot, R, seq.pos, d, seq.gt_mask) for d in distances}
    return out


def table_rows(results: dict[str, dict], averaged: list[str], methods: tuple[str, ...] = METHODS) -> list[list[str]]:
    def cell(a: tuple[float, float]) -> str:
        return f"{math.degrees(a[0]):.2f}/{math.degrees(a[1]):.2f}"

    # a variant of a sequence (e.g. V1_01 against its original ground truth) is listed, not averaged
    rows = [
        [name if name in averaged else f"{name}, not in the average", *[cell(r["aoe"][m]) for m in methods]]
        for name, r in results.items()
    ]
    avg = [np.mean([results[n]["aoe"][m] for n in averaged], axis=0) for m in methods]
    rows.append([f"average of {len(averaged)}", *[cell(a) for a in avg]])
    return rows


OWN_OUTPUTS = (
    "table.md",
    "table.csv",
    "roe.md",
    "roe.csv",
    "figures/orientation_*.png",
    "figures/error_*.png",
    "figures/correction_*.png",
    "figures/roe.png",
    "figures/uncertainty_calibration.png",
    "trajectories/*/*.txt",
)


def clear_earlier_outputs(out: Path) -> None:
    """Remove what an earlier evaluation wrote into `out` (its tables, figures and trajectories: a rerun with other
    models or sequences would leave some of them beside the new ones), saying so when it had finished."""
    earlier = remove_earlier_outputs(out, "results.json", OWN_OUTPUTS)
    if earlier is not None:
        model = (earlier.get("models") or {}).get("proposed", "?")
        print(f"note: replacing the outputs of an earlier evaluation in {out} (model {model})", file=sys.stderr)


def evaluate(cfg: DictConfig) -> dict:
    """Table 1, the figures and the TUM trajectories of a composed evaluate config (`compose_config("evaluate",
    [...])`; from Python it needs `out_dir=...`). Returns the summary written to `out_dir/results.json`; torch's
    thread count is left as it was found.

    The outputs are written into a hidden folder in `out_dir` and move into place when the evaluation has finished
    (an earlier evaluation's outputs are replaced only then): a run that fails leaves none of its own, and what was in
    `out_dir` before stays as it was."""
    out = with_output_dir(cfg, "out_dir")  # from Python there is no Hydra run folder to default to
    with torch_threads(cfg.get("threads")):
        with staged_outputs(out, "results.json", lambda: clear_earlier_outputs(out)) as stage:
            summary, console = _evaluate(cfg, stage)
    print(console, end="")
    print(f"outputs in {out}")
    return summary


def roe_distances(value: object) -> list[float]:
    """`roe_distances` as metres: a list of positive numbers, else a ConfigError naming it (not float()'s own)."""
    items = list(value) if isinstance(value, list | tuple | ListConfig) else None
    ok = items is not None and all(
        isinstance(d, int | float) and not isinstance(d, bool) and math.isfinite(d) and d > 0 for d in items
    )
    if not ok:
        raise ConfigError(
            f"roe_distances={value!r}: a list of travelled distances in metres, each > 0, "
            "e.g. 'roe_distances=[7,21,35]'"
        )
    return [float(d) for d in items]


def _evaluate(cfg: DictConfig, out: Path) -> tuple[dict, str]:
    """The evaluation, its outputs written into `out` (the staging folder); the summary and what to print."""
    start = time.time()
    split = cfg.get("split", "test")
    if split not in ("test", "val"):
        raise ConfigError(f"split={split!r}: use split=test (the test sequences) or split=val (the validation parts)")
    distances = roe_distances(cfg.roe_distances)  # before the data are read, not after the scoring
    for key in ("figures", "trajectories"):  # 'figures=fals' is a non-empty string, true to Python
        if not isinstance(value := cfg.get(key, True), bool):
            raise ConfigError(f"{key}={value!r}: give {key}=true or {key}=false")
    for key in ("proposed", "calibrated"):  # null: pathlib's TypeError deep in load_model, after the data were read
        if not isinstance(value := cfg.weights.get(key), str) or not value.strip():
            raise ConfigError(
                f"weights.{key}={value!r}: the table scores a denoiser and a calibrated model side by side; give "
                f"weights.{key}= a shipped model's name ({', '.join(available_models())}), a training run's folder "
                "or model file (a run's calibrated.pt lies beside its model.pt); the same file in both is allowed"
            )
    if split == "test" and OmegaConf.is_missing(cfg.dataset, "train_seqs"):  # asl_folder's '???': not read to test
        cfg = cfg.copy()
        with open_dict(cfg):
            cfg.dataset.train_seqs = []
    dm = hydra.utils.instantiate(cfg.dataset)
    if hasattr(dm, "inconsistent_truth"):  # scoring, not training: a disagreeing truth is said beside the scores
        dm.inconsistent_truth = "warn"
    with noting_data_warnings() as data_warnings:  # the sequences are read and checked here
        dm.check_sequences(
            train=split == "val",
            test=split == "test",
            test_hint="evaluate on the validation parts with split=val",
            fits=False,
        )
        dm.setup("test" if split == "test" else "fit")
    if split == "val" and not dm.val_part:  # the table's average of no rows was numpy's IndexError, after the models
        duration = cfg.dataset.get("train_duration_s")
        why = "train whole" if duration is None else f"are no longer than dataset.train_duration_s={duration} s"
        raise ConfigError(
            f"split=val: no validation part: the training sequences ({', '.join(dm.train_names) or 'none'}) {why}, "
            "so all of them trains; give a shorter dataset.train_duration_s, validation sequences with "
            "'dataset.val_seqs=[...]', or score test sequences (split=test)"
        )
    try:
        proposed, proposed_meta, proposed_warning = load_checked(cfg.weights.proposed)
        calibrated, calibrated_meta, calibrated_warning = load_checked(cfg.weights.calibrated)
    except FileNotFoundError as e:  # e.g. dataset=asl_folder: no shipped model of that name
        raise FileNotFoundError(
            f"{e} Name the models to score with weights.proposed=PATH (e.g. a training run's model.pt) and "
            "weights.calibrated=PATH (its calibrated.pt)."
        ) from None
    estimates = {str(k): v for k, v in (cfg.get("estimates") or {}).items()}  # other methods' trajectory files
    check_names(estimates, METHODS)
    scored = (*METHODS, *estimates)
    methods = {  # "proposed" is run in the loop below, with its spread when it is an ensemble
        "raw IMU": gyro_method(None),
        "zero motion": lambda seq: None,
        "calibrated IMU": gyro_method(calibrated),
    }
    sequences: dict[str, Sequence] = {}
    averaged: list[str] = []  # one row per test sequence, with the dataset's configured ground truth
    for seq in dm.test_part if split == "test" else dm.val_part:
        gt_file = dm.gt_files.get(seq.name)
        label = f"{seq.name} ({Path(gt_file).stem})" if gt_file else seq.name
        sequences[label] = seq
        averaged.append(label)
        for variant, variant_file in dm.eval_gt_variants.get(seq.name, {}).items():
            sequences[f"{seq.name} ({variant})"] = load_sequence(
                dm.root, seq.name, variant_file, dm.max_gap_factor, dm.cache_dir
            )

    parts = [dm.origin(seq) for seq in sequences.values()]
    # other methods' files: found, read, placed and checked against the gyro before any work (not after a sequence's);
    # a validation part (split=val) reads its recording's file
    check_files(estimates, [name for name, _ in parts])
    externals = {
        label: {name: load_external(name, spec, seq, part[0]) for name, spec in estimates.items()}
        for (label, seq), part in zip(sequences.items(), parts, strict=True)
    }
    estimate_warnings = [
        w
        for label, ests in externals.items()
        for name, est in ests.items()
        for w in frame_problems(name, label, est, sequences[label])
    ]
    for w in estimate_warnings:
        warnings.warn(w, DataConsistencyWarning, stacklevel=2)
    first_stamps = [int(seq.t0_ns) for seq in sequences.values()]
    model_warnings = [
        w for m in (proposed_meta, calibrated_meta) if (w := training_overlap_warning(m, parts, first_stamps))
    ]
    model_warnings += [
        w
        for m, setting in ((proposed_meta, "weights.proposed"), (calibrated_meta, "weights.calibrated"))
        if (w := other_imu_warning(m, dm.name, dm.sensor, dm.root, setting))
    ]
    rates = {seq.name: seq.rate_hz for seq in sequences.values()}
    model_warnings += [
        w
        for w in (
            other_rate_warning(proposed, proposed_meta, rates),
            other_rate_warning(calibrated, calibrated_meta, rates),
        )
        if w
    ]
    warned = [w for w in (proposed_warning, calibrated_warning, *model_warnings, *data_warnings) if w]
    warned += estimate_warnings
    for w in model_warnings:
        warnings.warn(w, ModelQualityWarning, stacklevel=2)
    results: dict[str, dict] = {}
    calib: dict[str, uncertainty.CalibrationResult] = {}
    external: dict[str, dict[str, dict]] = {name: {} for name in estimates}  # name -> sequence -> file, coverage
    coverage_notes: list[str] = []
    spread_ratios: dict[str, float] = {}  # against the ensemble's training recordings (gyrodenoise.spread_check)
    for label, seq in sequences.items():
        gyros = {m: fn(seq) for m, fn in methods.items()}
        gyros["proposed"], spread = predict_with_spread(proposed, seq.imu)
        if spread is not None:
            calib[label] = uncertainty.calibration(gyros["proposed"], spread, seq.dt, seq.rot, seq.gt_mask)
        if (ratio := spread_ratio(spread, proposed_meta)) is not None:
            spread_ratios[label] = ratio
            window = worst_window(spread, proposed_meta, 1.0 / float(np.median(seq.dt[1:])))
            if w := spread_warning(ratio, label, proposed_meta, window):
                warned.append(w)
                warnings.warn(w, ModelQualityWarning, stacklevel=2)
        r = evaluate_sequence(seq, gyros, distances)
        results[label] = r
        if cfg.get("trajectories", True):
            # the row of the dataset's own ground truth under the recording's name, so that the `*` form of
            # +estimates reads these files back; another ground truth's row (V1_01's original) under its row's
            folder = slug(seq.name if label in averaged else label)
            write_trajectories(out / "trajectories" / folder, seq, r["estimates"])
        external_errors = {}
        for name, est in externals[label].items():
            mask = est.mask(seq)
            r["aoe"][name] = aoe(seq.rot, est.R, mask)
            r["roe"][name] = {d: roe(seq.rot, est.R, seq.pos, d, mask) for d in distances}
            external[name][label] = {"file": portable_path(est.file), "coverage": est.coverage(seq)}
            coverage_notes += [n for n in [coverage_note(name, label, est, seq)] if n]
            external_errors[name] = nan_outside(orientation_errors(seq.rot, est.R), est.covered)
        if cfg.figures:
            figs = out / "figures"
            figs.mkdir(parents=True, exist_ok=True)
            shown = {m: r["estimates"][m] for m in ("raw IMU", "calibrated IMU", "proposed")}
            fig = plots.orientation_figure(seq.t, seq.rot, shown, label, seq.gt_mask)
            plots.save(fig, figs / f"orientation_{slug(label)}.png")
            errs = {m: orientation_errors(seq.rot, R) for m, R in shown.items()} | external_errors
            plots.save(plots.error_figure(seq.t, errs, label, seq.gt_mask), figs / f"error_{slug(label)}.png")
            w_tilde = gyros["proposed"] - seq.gyro @ proposed.C_hat.detach().double().numpy().T
            plots.save(plots.correction_figure(seq.t, w_tilde, label, spread), figs / f"correction_{slug(label)}.png")

    names = {"proposed": proposed_meta["name"], "calibrated IMU": calibrated_meta["name"]}
    header = ["sequence", *[f"{m}: {model_label(names[m])}" if m in names else m for m in scored]]
    rows = table_rows(results, averaged, scored)
    left_out = {n: int((~seq.gt_mask).sum()) for n, seq in sequences.items()}
    notes = [AOE_DEFINITION]
    notes += [f"{m}: {name}" for m, name in names.items() if model_label(name) != name]  # the whole path, once
    notes += [
        f"{n}: {k} of {len(sequences[n])} samples inside ground-truth gaps left out" for n, k in left_out.items() if k
    ]
    notes += coverage_notes
    write_text(
        out / "table.md",
        markdown_table(header, rows) + "".join(f"\n- {x}" for x in notes + [f"WARNING: {w}" for w in warned]) + "\n",
    )
    write_text(out / "table.csv", csv_text([h if h == "sequence" else f"{h} (AOE 3D/yaw deg)" for h in header], rows))

    # ROE pooled over the averaged test sequences
    roe_pooled = {
        d: {m: tuple(np.concatenate([results[n]["roe"][m][d][a] for n in averaged]) for a in (0, 1)) for m in scored}
        for d in distances
    }
    roe_rows = []
    for d in distances:
        for m in scored:
            s3, sy = (summarize(np.degrees(roe_pooled[d][m][a])) for a in (0, 1))
            roe_rows.append(
                [f"{d:g}", m, *[f"{s[k]:.2f}" for s in (s3, sy) for k in ("q1", "median", "q3")], str(s3["n"])]
            )
    roe_header = ["distance (m)", "method", "3D q1", "3D median", "3D q3", "yaw q1", "yaw median", "yaw q3", "pairs"]
    roe_note = ROE_DEFINITION.format(stride=ROE_STRIDE, d="/".join(f"{d:g}" for d in distances))
    write_text(out / "roe.md", markdown_table(roe_header, roe_rows) + f"\n- {roe_note}\n")
    write_text(out / "roe.csv", csv_text(roe_header, roe_rows))
    if cfg.figures:
        plots.save(plots.roe_boxplot(roe_pooled, f"ROE on {dm.name} {split} sequences"), out / "figures" / "roe.png")

    summary = {
        "command": recorded_command("evaluate"),
        "config": portable_tree(OmegaConf.to_container(cfg, resolve=True)),
        "machine": machine_description(),
        "code_version": code_version(),
        "versions": library_versions(),
        "dataset": dm.name,
        "data_root": portable_path(dm.root),
        "split": split,
        "models": names,  # no machine paths
        # which files were scored, whatever their names: a retrained run folder keeps its model.pt's name
        "model_sha256": {
            m: file_sha256(meta["path"])
            for m, meta in (("proposed", proposed_meta), ("calibrated IMU", calibrated_meta))
            if meta.get("path") and Path(meta["path"]).is_file()
        },
        "averaged_sequences": averaged,
        "aoe_definition": AOE_DEFINITION,
        "samples": {n: len(seq) for n, seq in sequences.items()},
        "samples_without_ground_truth": left_out,
        "ground_truth_files": {
            n: portable_path(seq.meta["gt_file"]) for n, seq in sequences.items() if "gt_file" in seq.meta
        },
        "roe_definition": roe_note,
        "aoe_deg": {n: {m: [math.degrees(v) for v in r["aoe"][m]] for m in scored} for n, r in results.items()},
        "average_aoe_deg": {
            m: [math.degrees(v) for v in np.mean([results[n]["aoe"][m] for n in averaged], axis=0)] for m in scored
        },
    }
    if estimates:  # each file read and the share of the ground-truth samples it was scored on
        summary["external_estimates"] = external
    if warned:
        summary["warnings"] = warned
    if calib:
        pooled = uncertainty.pooled([calib[n] for n in averaged])
        summary["uncertainty"] = {
            "ensemble_members": len(proposed.members),
            "sequences": {n: c.summary() for n, c in calib.items()},
            "pooled": pooled.summary(),
            "spread_ratio_to_training": spread_ratios or None,  # None: the file records no spread reference
        }
        if cfg.figures:
            plots.save(
                plots.calibration_figure(pooled, f"ensemble spread on {dm.name} {split}"),
                out / "figures" / "uncertainty_calibration.png",
            )
    summary["wall_s"] = round(time.time() - start, 1)  # data reading, models, figures and tables included
    write_json(out / "results.json", summary)
    console = [f"\nAOE 3D/yaw (deg) on {dm.name} {'test sequences' if split == 'test' else 'validation parts'}:\n"]
    console.append(markdown_table(header, rows))
    if calib:
        u = summary["uncertainty"]["pooled"]
        console.append(
            f"ensemble of {len(proposed.members)}: spread vs 1-s increment error, Spearman {u['spearman']:.2f}, "
            f"RMS actual / predicted {u['rms_ratio']:.2f} ({u['windows']} windows; above 1 the spread "
            "underestimates the error). "
            + (
                "The shipped ensembles keep a factor of 1 on purpose: a factor fitted on the cross-validation folds "
                "was not resolved (reports/accuracy.md)."
                if is_shipped(proposed_meta["path"])
                else "To correct it, measure this ratio on validation data (split=val), not on the test, then "
                "`python -m gyrodenoise.ensemble scale ENS.pt --by RATIO --fitted-by TEXT --out ENS2.pt`"
            )
        )
    console += [f"WARNING: {w}" for w in warned]
    return summary, "".join(f"{line}\n" for line in console)


@hydra_key_hints("evaluate")
@hydra.main(version_base="1.3", config_path="conf", config_name="evaluate")
def main(cfg: DictConfig) -> None:
    # the console's copy goes with the outputs (out_dir=... moves them out of Hydra's run folder)
    with console_to_job_log(job_log_path(cfg.out_dir)), user_errors(), warnings.catch_warnings():
        # the command prints these after its table (the `warned` lines); once is enough
        warnings.simplefilter("ignore", ModelQualityWarning)
        evaluate(cfg)
