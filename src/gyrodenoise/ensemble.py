"""Make one ensemble model file from K trained model files (`gyrodenoise.models.ensemble`).

    python -m gyrodenoise.ensemble build outputs/train/a/model.pt outputs/train/b/model.pt --out euroc-ensemble.pt
    python -m gyrodenoise.ensemble build --from-multirun multirun/train/<date> [--out ...]
    python -m gyrodenoise.ensemble scale ens.pt --by 1.3 --fitted-by "..." --out ens.pt   # calibrate the spread
    python -m gyrodenoise.ensemble reference ens.pt --out ens.pt [dataset=euroc dataset.root=...]

Training K members with one command is a Hydra multirun over seeds; `experiment=ensemble` sweeps
seeds 0-3 and builds `<sweep dir>/ensemble.pt` when the last run has finished:

    python -m gyrodenoise.train -m experiment=ensemble dataset=euroc          # or seed=0,1,2,3,4,5,6,7
    python -m gyrodenoise.train -m dataset=euroc seed=0,1,2,3 && \\
        python -m gyrodenoise.ensemble build --from-multirun multirun/train/<date> --out euroc-ensemble.pt

The ensemble's metadata records each member's file, seed, fold, training data and metrics. Members
must share the input conventions: same sampling rate, and (unless --allow-mixed) the same dataset
and sensor. The file loads like any model: `gyrodenoise.pretrained.load_model(path)`, or by name
once copied into gyrodenoise/weights/. `reference` records the members' spread on their training
recordings, against which `correct` and `evaluate` check new recordings (`gyrodenoise.spread_check`);
`experiment=ensemble` records it when it builds the file.
"""

from __future__ import annotations

# ruff: noqa: E402
# (the imports follow the hand-over below)
if __name__ == "__main__":  # python -m gyrodenoise.ensemble: a Ctrl-C during the imports below ends in one line
    from gyrodenoise.launch import run_as_main

    run_as_main("ensemble")  # imports this module as gyrodenoise.ensemble and runs its main

import argparse
import hashlib
import math
import re
import sys
import warnings
from pathlib import Path

import torch

from gyrodenoise.atomic import output_path_problem
from gyrodenoise.models.denoiser import GyroCorrection
from gyrodenoise.models.ensemble import EnsembleCorrection
from gyrodenoise.notices import interrupt_in_one_line, plain_project_warnings
from gyrodenoise.paths import portable_path
from gyrodenoise.pretrained import ModelQualityWarning, calibrated_beside, load_model, save_model
from gyrodenoise.provenance import file_sha256

SCALE_RANGE = (1e-3, 1e3)  # spread factors `scale` accepts
RATE_RTOL = 0.01  # members trained at rates further apart than this see different physics per sample


def _seed(path: Path, meta: dict) -> int | None:
    """The training seed: from the metadata, else the Hydra run config beside the file, else the command."""
    if meta.get("seed") is not None:
        return int(meta["seed"])
    hydra_cfg = path.parent / ".hydra" / "config.yaml"
    if hydra_cfg.is_file():
        from omegaconf import OmegaConf

        seed = OmegaConf.load(hydra_cfg).get("seed")
        if seed is not None:
            return int(seed)
    m = re.search(r"(?:^|\s)\+?seed=(\d+)", str(meta.get("command", "")))
    return int(m.group(1)) if m else None


def member_record(path: str | Path, meta: dict) -> dict:
    """What the ensemble remembers of one member file."""
    path = Path(path)
    test = meta.get("test") or {}
    return {
        "path": str(path),
        "sha256": file_sha256(path),
        "model": meta.get("model"),
        "dataset": meta.get("dataset"),
        "sensor": meta.get("sensor"),
        "rate_hz": meta.get("rate_hz"),
        "seed": _seed(path, meta),
        "fold": meta.get("fold"),
        "train_seqs": meta.get("train_seqs"),
        "train_duration_s": meta.get("train_duration_s"),
        "train_t0_ns": meta.get("train_t0_ns"),
        "causal": meta.get("causal"),  # measured for a user's own network (None: built in, causal by construction)
        "val_aoe_deg": meta.get("val_aoe_deg"),
        "test_aoe_deg": test.get("test/aoe_deg"),
        "test": test,
        "beats_calibrated": meta.get("beats_calibrated"),
        "calibrated_val_aoe_deg": meta.get("calibrated_val_aoe_deg"),
        "calibrated_model": calibrated_beside(path, meta.get("calibrated_model")),
        "command": meta.get("command"),
    }


def check_compatible(records: list[dict], allow_mixed: bool = False) -> None:
    """Members must read their input the same way: same rate; same dataset and sensor unless allowed."""
    rates = [r["rate_hz"] for r in records if r.get("rate_hz")]
    if rates and (max(rates) - min(rates)) > RATE_RTOL * min(rates):
        listing = ", ".join(f"{r['path']}: {r.get('rate_hz')}" for r in records)
        raise ValueError(f"ensemble members were trained at different IMU rates (Hz) -- {listing}")
    if allow_mixed:
        return
    for key in ("dataset", "sensor"):
        values = {repr(r.get(key)) for r in records if r.get(key) is not None}
        if len(values) > 1:
            listing = ", ".join(f"{r['path']}: {r.get(key)}" for r in records)
            raise ValueError(
                f"ensemble members come from different {key}s ({listing}); their input conventions "
                "(sensor, mounting, units) may differ. Pass --allow-mixed if they are the same sensor."
            )


def _common(records: list[dict], key: str):
    values = [r.get(key) for r in records]
    return values[0] if all(v == values[0] for v in values) else None


def weights_digest(model: torch.nn.Module) -> str:
    """sha256 of a network's parameters and buffers (names, dtypes, shapes, values): the same weights saved in two
    files, with other metadata or another name, have the same digest."""
    h = hashlib.sha256()
    for name, t in sorted(model.state_dict().items()):
        t = t.detach().cpu().contiguous()
        h.update(f"{name}:{t.dtype}:{tuple(t.shape)};".encode())
        h.update(t.numpy().tobytes() if t.dtype != torch.bfloat16 else t.float().numpy().tobytes())
    return h.hexdigest()


def _refuse_twins(members: list, records: list[dict]) -> None:
    """One network twice would weigh it double and shrink the spread: refused, whether as the same file or as the same
    weights in two files (re-saved, copied with other metadata)."""
    seen: dict[str, dict] = {}
    for m, r in zip(members, records, strict=True):
        digest = weights_digest(m)
        if digest in seen:
            first = seen[digest]
            same = "identical files" if r.get("sha256") and r.get("sha256") == first.get("sha256") else "same weights"
            raise ValueError(f"the same member twice: {r['path']} and {first['path']} ({same})")
        seen[digest] = r


def make_ensemble(paths: list[str | Path], allow_mixed: bool = False) -> tuple[EnsembleCorrection, dict, dict]:
    """Load the member files -> (ensemble model, model config, metadata). An ensemble file among
    them contributes its members (and their records)."""
    if not paths:
        raise ValueError("no member model files given")
    members: list[GyroCorrection] = []
    cfgs: list[dict] = []
    records: list[dict] = []
    for p in paths:
        model, meta = load_model(p, warn=False)
        if isinstance(model, EnsembleCorrection):
            if model.spread_scale != 1.0:
                warnings.warn(
                    f"{p}: its spread_scale {model.spread_scale:g} was fitted for that ensemble and is not carried "
                    "into the new one (set one with `python -m gyrodenoise.ensemble scale`)",
                    ModelQualityWarning,
                    stacklevel=2,
                )
            members += list(model.members)
            cfgs += [dict(c) for c in meta["model"]["members"]]
            records += list(meta.get("members") or [member_record(meta["path"], meta)] * len(model))
        else:
            members.append(model)
            cfgs.append(dict(meta["model"]))
            records.append(member_record(meta["path"], meta))
    check_compatible(records, allow_mixed)
    _refuse_twins(members, records)
    if len(members) == 1:  # allowed (it equals the member), but its uncertainty output says nothing
        warnings.warn(
            f"an ensemble of one member ({records[0]['path']}) has no spread: correct writes no w_std columns for it "
            "and the figures draw no band; give two or more member files for an uncertainty",
            ModelQualityWarning,
            stacklevel=2,
        )
    beats = [r.get("beats_calibrated") for r in records]
    if any(b is False for b in beats):
        bad = [r["path"] for r in records if r.get("beats_calibrated") is False]
        warnings.warn(f"ensemble members that did not beat the calibrated baseline: {bad}", ModelQualityWarning, 2)
    if leaky := [r["path"] for r in records if r.get("causal") is False]:
        msg = f"ensemble members that are not causal (they read later samples): {leaky}"
        warnings.warn(msg, ModelQualityWarning, stacklevel=2)
    cal_vals = [r["calibrated_val_aoe_deg"] for r in records if r.get("calibrated_val_aoe_deg") is not None]
    finite = [r["val_aoe_deg"] for r in records if r.get("val_aoe_deg") is not None]
    rates = [r["rate_hz"] for r in records if r.get("rate_hz")]
    meta = {
        "dataset": _common(records, "dataset"),
        "sensor": _common(records, "sensor"),
        "rate_hz": float(sum(rates) / len(rates)) if len(rates) == len(records) else None,
        "train_seqs": _common(records, "train_seqs"),
        "train_duration_s": _common(records, "train_duration_s"),
        "train_t0_ns": _common(records, "train_t0_ns"),
        "n_members": len(members),
        "members": records,
        "member_val_aoe_deg": [r.get("val_aoe_deg") for r in records],
        "member_val_aoe_deg_mean": (sum(finite) / len(finite)) if finite else None,
        # the ensemble itself was not compared with the calibrated baseline: unknown until evaluated
        "beats_calibrated": None,
        "members_beat_calibrated": beats,
        "members_causal": [r.get("causal") for r in records],
        "calibrated_val_aoe_deg": (sum(cal_vals) / len(cal_vals)) if cal_vals else None,
    }
    return EnsembleCorrection(members), {"name": "ensemble", "members": cfgs}, meta


def scale_spread(
    model_path: str | Path, scale: float, out: str | Path, fitted_by: str, command: str | None = None
) -> Path:
    """Write a copy of the ensemble file `model_path` whose std output is the members' std times `scale`
    (replacing any earlier factor); `fitted_by` says where the factor comes from (kept in the metadata)."""
    if not SCALE_RANGE[0] <= float(scale) <= SCALE_RANGE[1]:  # NaN included
        raise ValueError(
            f"--by {scale:g}: a spread factor from {SCALE_RANGE[0]:g} to {SCALE_RANGE[1]:g} (1: the members' raw std; "
            "fitted factors are ~0.5-2); beyond, the float32 std under- or overflows and the spread check goes off"
        )
    if not fitted_by.strip():
        raise ValueError("--fitted-by is empty: say where the factor comes from (a command, a result file)")
    model, meta = load_model(model_path, warn=False)
    if not isinstance(model, EnsembleCorrection):
        raise TypeError(f"{model_path}: a single model has no spread to scale; give an ensemble file")
    if len(model) < 2:
        raise ValueError(f"{model_path}: an ensemble of one member has no spread to scale")
    cfg = {**dict(meta["model"]), "spread_scale": float(scale)}
    scaled = EnsembleCorrection(list(model.members), scale)
    meta_name = meta.get("name")
    named = meta_name != portable_path(meta["path"])  # a shipped name or one the file records, not its path
    meta = {k: v for k, v in meta.items() if k not in ("model", "path", "name")}
    if named:  # not the original's name alone: "with euroc" would describe another model than the one that ran
        base = re.sub(r" \(spread x[^)]*\)$", "", meta_name)  # the factor replaces an earlier one: so does the name
        meta["name"] = f"{base} (spread x{float(scale):g})"
    meta["spread_scale"] = {
        "value": float(scale),
        "previous": model.spread_scale,
        "fitted_by": fitted_by,
        "command": command,
    }
    return save_model(scaled, cfg, out, meta)


def add_spread_reference(
    model_path: str | Path, out: str | Path, overrides: list[str] | None = None, command: str | None = None
) -> Path:
    """Write a copy of the ensemble file `model_path` with its `spread_reference`, taken on the members' training
    recordings read through the training config's dataset (`overrides`; default: dataset=<the members' dataset>)."""
    import hydra
    from omegaconf import OmegaConf, open_dict

    from gyrodenoise.cli_errors import ConfigError
    from gyrodenoise.config import compose_config

    model, meta = load_model(model_path, warn=False)
    if not isinstance(model, EnsembleCorrection):
        raise TypeError(f"{model_path}: a single model has no spread; give an ensemble file")
    if not overrides and not meta.get("dataset"):  # members of several datasets (--allow-mixed), or none recorded
        raise ValueError(
            f"{model_path}: its members record no one dataset to take the spread reference on; name it, e.g. "
            "`python -m gyrodenoise.ensemble reference FILE --out OUT dataset=euroc`"
        )
    overrides = list(overrides or [f"dataset={meta['dataset']}"])
    dataset = compose_config("train", overrides).dataset
    # the reference reads the members' recorded training sequences, not the config's lists: dataset=asl_folder's
    # '???' lists are not needed (they ended in omegaconf's MissingMandatoryValue traceback), its '???' root is
    names, _ = reference_recordings(meta)
    with open_dict(dataset):
        for key in ("train_seqs", "test_seqs"):
            if OmegaConf.is_missing(dataset, key):
                dataset[key] = list(names)
    if OmegaConf.is_missing(dataset, "root"):
        raise ConfigError(
            f"dataset.root has no value ({dataset.get('name')} names no data folder of its own): give the folder that "
            f"holds the members' training recordings ({', '.join(names) or 'not recorded'}), "
            f"e.g. `python -m gyrodenoise.ensemble reference {model_path} --out {out} "
            f"dataset={meta.get('dataset') or 'asl_folder'} dataset.root=FOLDER`"
        )
    return _save_with_reference(model, meta, hydra.utils.instantiate(dataset), out, command)


def reference_recordings(meta: dict) -> tuple[list[str], str]:
    """The recordings an ensemble's spread reference is taken on, and what they are: the members' common training
    recordings, else (members trained on different flights: the folds of a cross-validation) the union of theirs;
    none where a member records none.
    On the union each flight was held out by some member, whose disagreement there is its held-out one: the reference
    comes out higher than a seed ensemble's would, and the check warns later, not sooner."""
    plain = "the members' training recordings"
    if common := list(meta.get("train_seqs") or []):
        return common, plain
    lists = [list(rec.get("train_seqs") or []) for rec in meta.get("members") or []]
    if not lists or not all(lists):  # a member that records none: its recordings are unknown, none is guessed
        return [], plain
    if all(set(seqs) == set(lists[0]) for seqs in lists):  # the same flights, listed in another order
        return lists[0], plain
    union = list(dict.fromkeys(n for seqs in lists for n in seqs))
    return union, "the union of the members' training recordings (each held out by some member)"


def _save_with_reference(model: EnsembleCorrection, meta: dict, dm, out: str | Path, command: str | None) -> Path:
    from gyrodenoise.spread_check import spread_reference

    names, taken_on = reference_recordings(meta)
    if not names:
        raise ValueError("the ensemble's metadata names no training sequences to take the spread reference on")
    if not Path(dm.root).is_dir():
        raise FileNotFoundError(
            f"{dm.root}: data folder not found (relative paths start at {Path.cwd()}); the spread reference reads the "
            f"members' training recordings ({', '.join(names)}) from it. Give the folder as an override, "
            f"dataset.root=FOLDER, or set GYRODENOISE_DATA to the folder that holds '{dm.name}/'."
        )
    reference = spread_reference(model, ((n, dm.load(n).imu) for n in names))
    cfg = dict(meta["model"])
    meta = {k: v for k, v in meta.items() if k not in ("model", "path")}
    where = {"recordings": taken_on, "data_root": portable_path(dm.root), "command": command}
    meta["spread_reference"] = {**reference, **where}
    return save_model(model, cfg, out, meta)


def multirun_members(sweep_dir: str | Path, allow_missing: bool = False) -> list[Path]:
    """`<sweep dir>/*/model.pt` in job order (Hydra's numbered subfolders). A job folder without model.pt (a run
    that failed, or was stopped and not resumed) is named in the error, unless `allow_missing`."""
    d = Path(sweep_dir)
    if not d.is_dir():
        raise FileNotFoundError(f"{d}: not a folder (give a Hydra multirun sweep folder)")
    found = list(d.glob("*/model.pt"))
    if not found:
        raise FileNotFoundError(f"{d}: no */model.pt (have the runs of this multirun finished?)")

    def key(p: Path) -> tuple:
        return (0, int(p.name), "") if p.name.isdigit() else (1, 0, p.name)

    jobs = [j for j in d.iterdir() if (j / ".hydra").is_dir()]
    if (missing := sorted((j for j in jobs if not (j / "model.pt").is_file()), key=key)) and not allow_missing:
        names = ", ".join(j.name for j in missing)
        raise FileNotFoundError(
            f"{d}: job(s) {names} have no model.pt (failed, or stopped before the end): finish one by rerunning it in "
            f"its folder (hydra.run.dir={missing[0]}: it resumes from its checkpoint), or leave them out with "
            "--allow-missing"
        )
    return [p / "model.pt" for p in sorted((f.parent for f in found), key=key)]


def build_ensemble(
    paths: list[str | Path],
    out: str | Path,
    name: str | None = None,
    allow_mixed: bool = False,
    command: str | None = None,
) -> Path:
    """Write the ensemble of the member files to `out` (same file format as any model)."""
    return _write_ensemble(paths, out, name, allow_mixed, command)[0]


def _write_ensemble(
    paths: list[str | Path], out: str | Path, name: str | None, allow_mixed: bool, command: str | None
) -> tuple[Path, dict]:
    """`build_ensemble`, and the metadata it wrote (its member count, without reading the file back)."""
    model, cfg, meta = make_ensemble(paths, allow_mixed)
    meta["name"] = name or Path(out).stem
    meta["command"] = command
    return save_model(model, cfg, out, meta), meta


try:  # the Hydra hook of experiment=ensemble; Hydra is a dependency, the guard keeps this module light
    from hydra.experimental.callback import Callback as _HydraCallback
except ImportError:  # pragma: no cover
    _HydraCallback = object  # type: ignore[assignment,misc]


class BuildEnsembleCallback(_HydraCallback):
    """Hydra callback: after a multirun, build `<sweep dir>/<filename>` from its runs' model.pt."""

    def __init__(self, filename: str = "ensemble.pt") -> None:
        self.filename = filename

    def on_multirun_end(self, config, **kwargs) -> None:
        sweep = Path(config.hydra.sweep.dir)
        try:
            paths = multirun_members(sweep)
        except FileNotFoundError as e:
            print(f"ensemble not built: {e}", file=sys.stderr)
            return
        with plain_project_warnings():  # the members' warnings as `warning: ...` lines, as `ensemble build` says them
            out = build_ensemble(paths, sweep / self.filename, command=f"BuildEnsembleCallback on {sweep}")
        print(f"ensemble of {len(paths)} models: {out}")
        try:  # the members' training data are the sweep's dataset
            import hydra

            model, meta = load_model(out, warn=False)
            _save_with_reference(model, meta, hydra.utils.instantiate(config.dataset), out, "BuildEnsembleCallback")
        except Exception as e:  # noqa: BLE001 - the ensemble stands without it; say how to add it
            print(f"no spread reference recorded ({e}): add it with `python -m gyrodenoise.ensemble reference`")


@interrupt_in_one_line
def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m gyrodenoise.ensemble",
        description="Make one ensemble model file (mean + per-sample spread) from trained model files.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog=__doc__.split("\n\n", 1)[1],
    )
    sub = ap.add_subparsers(dest="cmd", required=True)
    b = sub.add_parser("build", help="build an ensemble file from member model files")
    b.add_argument("models", nargs="*", help="member model files (.pt / .ckpt) or shipped model names")
    b.add_argument("--from-multirun", type=Path, help="a Hydra multirun folder: its */model.pt are the members")
    b.add_argument(
        "--allow-missing", action="store_true", help="with --from-multirun: leave out jobs that have no model.pt"
    )
    b.add_argument("--out", type=Path, help="output file (default with --from-multirun: DIR/ensemble.pt)")
    b.add_argument("--name", help="name recorded in the metadata (default: the output file's stem)")
    b.add_argument("--allow-mixed", action="store_true", help="allow members from different datasets / sensors")
    sc = sub.add_parser("scale", help="set the factor of an ensemble's spread (std output = members' std x S)")
    sc.add_argument("model", help="ensemble file or shipped name")
    sc.add_argument("--by", type=float, required=True, help="the factor S (1: the members' raw std)")
    sc.add_argument(
        "--fitted-by", required=True, help="where S comes from (a command, a result file): kept in the file"
    )
    sc.add_argument("--out", type=Path, required=True, help="output file (may be the input file: written atomically)")
    rf = sub.add_parser(
        "reference",
        help="record the members' spread on their training recordings (correct and evaluate check new data against it)",
    )
    rf.add_argument("model", help="ensemble file or shipped name")
    rf.add_argument("--out", type=Path, required=True, help="output file (may be the input file: written atomically)")
    rf.add_argument(
        "overrides", nargs="*", help="training-config overrides that find the data (default: dataset=<its dataset>)"
    )
    args, extra = ap.parse_known_args(argv)  # overrides may follow --out: argparse leaves them over
    if extra and (args.cmd != "reference" or any(a.startswith("-") for a in extra)):
        ap.error(f"unrecognized arguments: {' '.join(extra)}")
    if args.cmd == "reference":
        args.overrides += extra
    # asked before the work (reading the data, for `reference`): a folder, or a path under a file, ended the command
    # with IsADirectoryError's traceback only when the file was saved
    if args.out is not None and (problem := output_path_problem(args.out)):
        print(f"error: --out {args.out}: {problem}", file=sys.stderr)
        return 2
    command = " ".join(["python -m gyrodenoise.ensemble", *(argv if argv is not None else sys.argv[1:])])
    if args.cmd == "reference":
        from hydra.errors import ConfigCompositionException

        from gyrodenoise.cli_errors import USER_ERRORS

        try:
            out = add_spread_reference(args.model, args.out, args.overrides, command)
        except (*USER_ERRORS, ValueError, TypeError, ConfigCompositionException) as e:  # a misspelt override too
            print(f"error: {e}", file=sys.stderr)
            return 2
        ref = load_model(out, warn=False)[1]["spread_reference"]
        cells = ", ".join(f"{k} {math.degrees(v):.3f}" for k, v in ref["per_recording_rad_s"].items())
        print(f"wrote {out}: spread reference {math.degrees(ref['reference_rad_s']):.3f} deg/s ({cells})")
        return 0
    if args.cmd == "scale":
        try:
            out = scale_spread(args.model, args.by, args.out, args.fitted_by, command)
        except (FileNotFoundError, ValueError, TypeError) as e:
            print(f"error: {e}", file=sys.stderr)
            return 2
        print(f"wrote {out} (spread scale {args.by:g})")
        return 0
    try:
        paths: list[str | Path] = list(args.models)
        if args.from_multirun:
            paths += multirun_members(args.from_multirun, args.allow_missing)
        out = args.out or (args.from_multirun / "ensemble.pt" if args.from_multirun else None)
        if out is None:
            ap.error("give --out FILE")
        if args.out is None and (problem := output_path_problem(out)):  # the default beside the multirun's runs
            print(f"error: {out} (the default --out): {problem}", file=sys.stderr)
            return 2
        if not paths:
            ap.error("give member model files or --from-multirun DIR")
        with plain_project_warnings():  # the members' warnings as `warning: ...` lines
            _, meta = _write_ensemble(paths, out, args.name, args.allow_mixed, command)
    except (FileNotFoundError, ValueError, TypeError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    members = meta["n_members"]  # an ensemble file among the paths gives all its members
    print(f"wrote {out} ({members} members from {len(paths)} file{'s' if len(paths) > 1 else ''})")
    if members > 1:  # without a reference, correct and evaluate cannot tell data unlike the training data
        print(f"note: no spread reference yet: python -m gyrodenoise.ensemble reference {out} --out {out}")
    return 0
