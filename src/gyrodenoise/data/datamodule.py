"""Datasets and the LightningDataModule with the paper's splits.

Training: the first `train_duration_s` (None: all) of each training sequence, served as random crops
whose start is a multiple of the longest loss increment, so that the ground-truth increments over
`base_increment` samples are computed once per sequence and only sliced afterwards.
Validation (`val_seqs`, default: the training sequences): the rest of a training sequence after
`train_duration_s`, or a sequence that is not trained on, whole. Test: the test sequences, whole.

Cross-validation (`cv_fold=k`): leave-one-flight-out over the training sequences. Flight k of
`train_seqs` is not trained on and is validated whole (group "val", the selection figure); the
rest of the other training flights is validated too, as group "val_tail" (the paper's figure),
so that both protocols are measured on the same run.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Mapping
from pathlib import Path

import lightning.pytorch as L
import numpy as np
import torch
from torch.utils.data import DataLoader, Dataset

from gyrodenoise.cli_errors import ConfigError
from gyrodenoise.data import consistency
from gyrodenoise.data.augment import AugmentConfig, augment_window
from gyrodenoise.data.cache import load_sequence
from gyrodenoise.data.checks import RATE_TOL
from gyrodenoise.data.fetch import DATASETS as FETCHABLE
from gyrodenoise.data.sequence import (
    Sequence,
    gt_increments,
    misspelt,
    not_asl_note,
    root_level_hint,
    sequences_in,
)


def sequence_item(seq: Sequence, step: int, block: int) -> dict:
    """A whole sequence as a batch item, truncated to 1 + multiple of `block` samples."""
    n = 1 + ((len(seq) - 1) // block) * block
    s = seq.slice(0, n)
    dR, ok = gt_increments(s, step)
    return {
        "imu": torch.from_numpy(s.imu).float(),
        "dt": torch.from_numpy(s.dt),
        "dR": torch.from_numpy(dR),
        "dR_mask": torch.from_numpy(ok),
        "rot": torch.from_numpy(s.rot),
        "pos": torch.from_numpy(s.pos),
        "gt_mask": torch.from_numpy(s.gt_mask),
        "t": torch.from_numpy(s.t),
        "name": s.name,
    }


NOMINAL_RATE_TOL = 0.05  # sensor.rate_hz this close to the measured rate is the same rate


class RandomCrops(Dataset):
    """`crops_per_epoch` random windows of `window` (+1) samples from each training sequence."""

    def __init__(
        self,
        seqs: list[Sequence],
        window: int,
        step: int,
        block: int,
        crops_per_epoch: int,
        augment: AugmentConfig,
    ) -> None:
        self.seqs, self.step, self.block = seqs, step, block
        self.crops_per_epoch, self.augment = crops_per_epoch, augment
        shortest = min(len(s) for s in seqs)
        self.window = min(window, ((shortest - 1) // block) * block)
        if self.window < block:
            raise ConfigError(  # a ValueError too
                f"training sequences are too short ({shortest} samples inside the ground truth's span) for one "
                f"{block}-sample block: check that the ground truth covers the recording"
            )
        self.increments = [gt_increments(s, step) for s in seqs]  # computed once
        self.imu = [torch.from_numpy(s.imu).float() for s in seqs]
        self.dt = [torch.from_numpy(s.dt) for s in seqs]

    def __len__(self) -> int:
        return len(self.seqs) * self.crops_per_epoch

    def __getitem__(self, i: int) -> dict:
        k = i % len(self.seqs)
        n_blocks = (len(self.seqs[k]) - 1 - self.window) // self.block + 1
        start = int(torch.randint(0, n_blocks, ()).item()) * self.block
        stop = start + self.window + 1
        dR, ok = self.increments[k]
        a, b = start // self.step, (start + self.window) // self.step
        return {
            "imu": augment_window(self.imu[k][start:stop], self.augment),
            "dt": self.dt[k][start:stop],
            "dR": torch.from_numpy(dR[a:b]),
            "dR_mask": torch.from_numpy(ok[a:b]),
        }


# how the validation parts of the training sequences are named in the commands' output (`ImuDataModule.setup`)
TAIL_NAME_NOTE = "NAME[Ns:] is the part of a training sequence after its first N seconds (the seconds trained on)."


def check_sequence_lists(
    train_seqs: list[str], test_seqs: list[str], val_seqs: list[str] | None, cv_fold: int | str | None
) -> None:
    """The dataset's sequence lists and fold, checked before any data are read or simulated: a ConfigError naming
    the setting (`SimDataModule` calls it before it generates its sequences)."""
    for key, names in (("train_seqs", train_seqs), ("test_seqs", test_seqs), ("val_seqs", val_seqs)):
        if isinstance(names, str):  # list('walk_1') would look for the sequences w, a, l, k, _, 1
            raise ConfigError(
                f"dataset.{key}={names!r} is one name, not a list: give 'dataset.{key}=[{names}]' (quoted for "
                f"the shell), or several: 'dataset.{key}=[a,b]'"
            )
        if names is not None and (twice := sorted({str(n) for n in names if list(names).count(n) > 1})):
            # a set of sequences: a repeat trains no more on it, and with cv_fold its holdout stayed in training
            raise ConfigError(f"dataset.{key} names {', '.join(twice)} more than once: give each sequence once")
    if val_seqs is not None and not list(val_seqs):  # "named" but none: nothing validates, and scoring crashed
        raise ConfigError(
            "dataset.val_seqs=[] names no validation sequence: name some, or leave it null (the training sequences' "
            "ends validate)"
        )
    if cv_fold is None:
        return
    train = list(train_seqs or [])
    if val_seqs is not None:
        raise ConfigError("dataset.cv_fold and dataset.val_seqs exclude each other: set one of them to null")
    if len(train) < 2:  # its one flight held out leaves nothing to train on (a bare numpy error)
        raise ConfigError(
            f"dataset.cv_fold={cv_fold} needs two training flights or more (it holds one out and trains on "
            f"the others), got {train}: name more in dataset.train_seqs, or set dataset.cv_fold=null"
        )
    if isinstance(cv_fold, str) and cv_fold.lower() == "all":
        raise ConfigError(
            "dataset.cv_fold=all trains every fold in turn inside `python -m gyrodenoise.train`; anywhere else "
            f"give one fold, 0..{len(train) - 1}"
        )
    if isinstance(cv_fold, bool) or not isinstance(cv_fold, int) or not 0 <= cv_fold < len(train):
        n = len(train)
        folds = ",".join(map(str, range(n)))
        raise ConfigError(
            f"dataset.cv_fold={cv_fold}: choose 0..{n - 1} (one per training sequence {train}); "
            "the experiments' folds are EuRoC's six: for experiment=cross_validation (it sweeps 0-5) give "
            f"dataset.cv_fold={folds} on the command line, or dataset.cv_fold=all; an ablation holds out "
            f"fold = seed, so give it seed={folds}"
        )


class ImuDataModule(L.LightningDataModule):
    """Splits by sequence name and time, as in the paper (Section IV-A)."""

    def __init__(
        self,
        name: str,
        root: str,
        train_seqs: list[str],
        test_seqs: list[str],
        val_seqs: list[str] | None = None,
        train_duration_s: float | None = 50.0,
        gt_files: Mapping[str, str] | None = None,
        eval_gt_variants: Mapping[str, Mapping[str, str]] | None = None,
        window: int = 9600,
        crops_per_epoch: int = 1,
        increments: tuple[int, ...] = (16, 32),
        augment: Mapping | None = None,
        max_gap_factor: float = 3.0,
        cache_dir: str | None = None,
        sensor: Mapping | None = None,
        cv_fold: int | str | None = None,  # 'all': refused here (a training mode of gyrodenoise.train)
        inconsistent_truth: str = "stop",  # a training sequence whose truth disagrees with its gyro: stop | warn
    ) -> None:
        super().__init__()
        self.name, self.root = name, str(root)
        check_sequence_lists(train_seqs, test_seqs, val_seqs, cv_fold)
        self.train_names = list(train_seqs)
        self.val_names = list(val_seqs if val_seqs is not None else train_seqs)
        self.val_explicit = val_seqs is not None  # named validation sequences must have data to validate on
        self.cv_fold, self.cv_holdout = cv_fold, None
        if cv_fold is not None:
            self.cv_holdout = self.train_names.pop(cv_fold)
        self.test_names = list(test_seqs)
        self.train_duration_s = train_duration_s
        self.gt_files = dict(gt_files or {})
        # evaluation only: {sequence: {label: gt_file}}, extra rows against another ground truth
        self.eval_gt_variants = {k: dict(v) for k, v in (eval_gt_variants or {}).items()}
        self.window, self.crops_per_epoch = window, crops_per_epoch
        self.step, self.block = min(increments), max(increments)
        if any(j < 1 or j & (j - 1) for j in increments) or self.block % self.step:
            near = sorted({2 ** max(0, round(math.log2(max(j, 1)))) for j in increments})
            raise ConfigError(  # a ValueError; inside Hydra's instantiate it printed as a wrapped error
                f"loss.increments={list(increments)}: the increments (samples) must be powers of two (the loss "
                f"multiplies the gyro's rotations in a tree of pairs): the nearest, e.g. 'loss.increments={near}'. "
                "At another rate than 200 Hz: docs/own-data.md, 'Rates other than 200 Hz'"
            )
        self.sensor = dict(sensor or {})
        for key in ("rate_hz", "gyro_noise_density", "acc_noise_density"):
            value = self.sensor.get(key)
            if value is not None and (
                isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value) or value < 0
            ):  # else a TypeError deep in the noise's formula, naming only 'dataset'
                raise ConfigError(
                    f"dataset.sensor.{key}={value!r}: a number >= 0 in SI units "
                    "(rate_hz in Hz, noise densities in rad/s/sqrt(Hz) and m/s^2/sqrt(Hz))"
                )
        if self.sensor.get("rate_hz") == 0:
            raise ConfigError("dataset.sensor.rate_hz=0: give the IMU's nominal rate in Hz, e.g. 200")
        self._augment_spec = dict(augment or {})
        # checked now (a wrong key fails before any data is read); rebuilt at the data's measured rate for training
        self.augment = self._augment_config(self.sensor.get("rate_hz", 200.0))
        self.max_gap_factor, self.cache_dir = max_gap_factor, cache_dir
        if inconsistent_truth not in ("stop", "warn"):
            raise ConfigError(
                f"dataset.inconsistent_truth={inconsistent_truth!r}: 'stop' (a training sequence whose ground truth "
                "disagrees with its gyro in scale, axes or clock stops the run) or 'warn' (train anyway)"
            )
        self.inconsistent_truth = inconsistent_truth
        self.train_part: list[Sequence] = []
        self._rates_warned: set[str] = set()  # sequences whose rate was compared with the training data's
        self._increment_checked = False  # the loss increments against the ground truth's period
        self.val_part: list[Sequence] = []
        self.val_groups: list[str] = []  # metric group of each validation sequence
        self.part_origin: dict[str, tuple[str, float]] = {}  # validation part name -> (sequence, start in s)
        self.test_part: list[Sequence] = []

    def _augment_config(self, rate_hz: float) -> AugmentConfig:
        """Noise std defaults to `noise_scale` (0.5, the paper) x the sensor's per-sample noise at `rate_hz`."""
        aug = dict(self._augment_spec)
        scale = aug.pop("noise_scale", 0.5)
        for kind in ("gyro", "acc"):
            if aug.get(f"{kind}_noise_std") is None:
                density = self.sensor.get(f"{kind}_noise_density", 0.0)
                aug[f"{kind}_noise_std"] = noise_std_from_density(density, rate_hz, scale)
        return AugmentConfig(**aug)

    def check_sequences(
        self,
        train: bool = True,
        test: bool = True,
        test_hint: str = "pass test=false to train without them",
        fits: bool = True,
    ) -> None:
        """Fail before the work, not in the middle of it: every sequence the command will read has its folder.

        A training whose test sequences are missing (TUM-VI's withheld rooms) would otherwise run for minutes
        and then stop at the test without writing its model. `test_hint` is what to do when only test
        sequences are missing. `fits` False: the caller reads the validation data but fits nothing (evaluate
        split=val), and needs no training sequence where dataset.val_seqs names the validation ones.
        """
        nothing_to_fit = not self.train_names and not self.cv_holdout
        if train and nothing_to_fit and (fits or not self.val_explicit):  # else numpy's 'need at least one array'
            raise ConfigError(
                "dataset.train_seqs is empty: name the training sequences (their ends validate unless "
                "dataset.val_seqs names others), e.g. 'dataset.train_seqs=[walk_1,walk_2]'"
            )
        names = [*self.train_names, *([self.cv_holdout] if self.cv_holdout else [])] if train else []
        names += [*(self.val_names if self.val_explicit and train else []), *(self.test_names if test else [])]
        missing = [n for n in dict.fromkeys(names) if not (Path(self.root) / n / "mav0").is_dir()]
        root = Path(self.root)
        if missing and not root.is_dir() and (root.parent / missing[0] / "mav0").is_dir():  # <dataset>/ given twice
            raise FileNotFoundError(
                f"{root}: data folder not found, but {root.parent} holds {missing[0]}: set dataset.root="
                f"{root.parent}, or GYRODENOISE_DATA to the folder that holds '{root.parent.name}/' "
                f"({root.parent.parent}), not to '{root.parent.name}/' itself (the shipped dataset configs read "
                "$GYRODENOISE_DATA/<dataset>)."
            )
        if missing and not root.is_dir():  # the whole folder: a test-only hint would mislead
            relative = "" if root.is_absolute() else f" (relative paths start at {Path.cwd()})"
            siblings = [d.name for d in root.parent.iterdir() if d.is_dir()] if root.parent.is_dir() else []
            near = misspelt(root.name, siblings)  # 'eurocc' beside 'euroc': a typo, not a dataset to download
            if near:
                raise FileNotFoundError(
                    f"{self.root}: data folder not found{relative}; did you mean {root.parent / near}? (set "
                    "dataset.root to it, or GYRODENOISE_DATA to the folder that holds it)"
                )
            raise FileNotFoundError(
                f"{self.root}: data folder not found{relative}; it should hold "
                f"{', '.join(missing)} in the ASL layout (<root>/<sequence>/mav0/imu0/data.csv). Set dataset.root "
                f"to that folder, or GYRODENOISE_DATA to the folder that holds '{self.name}/' (the shipped dataset "
                "configs read $GYRODENOISE_DATA/<dataset>)."
                + (
                    f" To download it: python -m gyrodenoise.data.fetch {self.name} --dest {self.root}"
                    if self.name in FETCHABLE
                    else ""
                )
            )
        if missing and (hint := root_level_hint(Path(self.root), missing[0], "dataset.root")):  # root one level off
            raise FileNotFoundError(f"{self.root}: sequence folder(s) not found: {', '.join(missing)}. {hint.rstrip()}")
        if missing:
            only_test = set(missing) <= set(self.test_names)
            here = sequences_in(self.root)
            notes = {n: not_asl_note(self.root, n) for n in missing}  # '' unless a folder of other files
            layout = "".join(notes.values())
            absent = [n for n in missing if not notes[n]]
            typo = "; ".join(f"{n}: did you mean {c}?" for n in absent if (c := misspelt(n, here)))
            raise FileNotFoundError(
                f"{self.root}: sequence folder(s) not found: {', '.join(missing)} (ASL layout "
                f"<root>/<sequence>/mav0/imu0/data.csv). "
                + layout
                + (f"{typo} " if typo else "")
                + (f"The folder holds {', '.join(here)}. " if here else "")
                + "Check the names, or set dataset.root to the folder that holds them"
                f"{'; or ' + test_hint if only_test else ''}."
            )
        if test and not self.test_names:
            raise ConfigError(f"dataset.test_seqs is empty: name the test sequences, or {test_hint}")
        if test and not self.test_part:
            # read (and check) them now: a bad test file found after the fit would cost the trained model
            self.test_part = [self.load(n) for n in self.test_names]

    def model_meta(self) -> dict:
        """What a model file records of the data it was trained on (read back by evaluate, correct, export)."""
        return {
            "dataset": self.name,
            "data_root": str(
                Path(self.root).resolve()
            ),  # the same folder later is the same dataset, whatever its label
            "sensor": dict(self.sensor),
            "rate_hz": float(f"{self.rate_hz:.9g}"),  # stamps' rounding (100.00000000000213) is not a rate
            "train_seqs": list(self.train_names),
            "train_duration_s": self.train_duration_s,
            # each training recording's first IMU stamp: another recording of the same name is not training data
            "train_t0_ns": {s.name: int(s.t0_ns) for s in self.train_part},
        }

    def origin(self, seq: Sequence) -> tuple[str, float]:
        """(sequence name, start in s) of a sequence this module serves: a validation part starts where the
        training part of its sequence ends, anything else (whole sequences) at its beginning."""
        return self.part_origin.get(seq.name, (seq.name, 0.0))

    def load(self, name: str, training: bool = False) -> Sequence:
        """A sequence through the cache, checked against its ground truth (`consistency`: deg/s, gaps, clock; read
        to train on (`training`), one whose truth disagrees with its gyro stops the run unless
        inconsistent_truth=warn)."""
        seq = load_sequence(self.root, name, self.gt_files.get(name), self.max_gap_factor, self.cache_dir)
        consistency.check(seq, stop=training and self.inconsistent_truth == "stop")
        return seq

    def setup(self, stage: str | None = None) -> None:
        if stage in (None, "fit", "validate") and not self.train_part:
            short: list[str] = []  # training sequences no longer than train_duration_s: nothing of them validates
            over = False  # one of them longer than train_duration_s, by at most the loss's longest increment
            for name in sorted(set(self.train_names) | set(self.val_names)):
                seq = self.load(name, training=name in self.train_names)
                if name not in self.train_names:  # a validation sequence of its own: whole
                    self.val_part.append(seq)
                    self.val_groups.append("val")
                    continue
                cut = len(seq) - 1 if self.train_duration_s is None else seq.index_at(self.train_duration_s)
                self.train_part.append(seq.slice(0, cut + 1, name))
                if name in self.val_names:
                    if (self.cv_holdout is not None or not self.val_explicit) and len(seq) - cut <= self.block:
                        if self.cv_holdout is None and self.train_duration_s is not None:
                            short.append(f"{name} ({seq.t[-1] - seq.t[0]:.1f} s)")
                            over |= seq.t[-1] - seq.t[0] > self.train_duration_s  # a tail too short to validate
                        continue  # a flight trained on whole has no tail; validation was not asked for by name
                    if len(seq) - cut <= self.block:
                        raise ValueError(
                            f"validation sequence {name!r} is also a training sequence and nothing of it is "
                            f"left after train_duration_s={self.train_duration_s}: lower "
                            "dataset.train_duration_s or name other sequences in dataset.val_seqs"
                        )
                    tail = seq.slice(cut, len(seq), f"{name}[{self.train_duration_s:g}s:]")
                    self.val_part.append(tail.from_first_ground_truth())  # a cut inside an occlusion
                    self.part_origin[self.val_part[-1].name] = (name, float(self.train_duration_s))
                    self.val_groups.append("val" if self.cv_holdout is None else "val_tail")
            if short:
                self._warn_short(short, over)
        if stage in (None, "test", "predict") and not self.test_part:
            self.test_part = [self.load(n) for n in self.test_names]
        self._check_rates()

    def _warn_short(self, short: list[str], over: bool = False) -> None:
        """Training sequences no longer than train_duration_s are trained on whole: nothing of them validates. When
        none validates, validation AOE is NaN and the safety net (beats the calibrated baseline?) cannot run; that
        was said only by NaN and Lightning's 'Total length of DataLoader ... is zero' (own-data walkthrough)."""
        what = (
            "so there is no validation data at all: the validation AOE is NaN and whether the model beats the "
            "calibrated baseline cannot be told"
            if not self.val_part
            else "so nothing of them validates"
        )
        extra = f" plus the loss's longest increment ({self.block} samples)" if over else ""
        warnings.warn(
            f"training sequence(s) {', '.join(short)} no longer than dataset.train_duration_s="
            f"{self.train_duration_s:g}{extra} "
            f"are trained on whole, {what}. Lower dataset.train_duration_s (e.g. to two "
            "thirds of the shortest), or name validation sequences in dataset.val_seqs",
            consistency.DataConsistencyWarning,
            stacklevel=2,
        )

    def _check_rates(self) -> None:
        """One model, one rate: the network's convolutions and increments count samples. Training sequences more
        than RATE_TOL apart stop the run; a validation or test sequence at another rate than the training data warns
        (once), since its figures then measure the model off its rate; so does a shortest loss increment under two
        ground-truth periods (a 1 kHz IMU under 100 Hz mocap with the 16-sample default)."""
        if not self.train_part:
            return
        rates = {s.name: s.rate_hz for s in self.train_part}
        if max(rates.values()) / min(rates.values()) - 1.0 > RATE_TOL:
            listed = ", ".join(f"{n} {r:.4g} Hz" for n, r in rates.items())
            raise ConfigError(
                f"the training sequences sample at different rates ({listed}): one model learns one rate, since its "
                "convolutions and loss increments count samples. Resample them to one rate, or train a model per rate."
            )
        gt_period = max(float(s.meta.get("gt_period_s") or 0.0) for s in self.train_part)
        if not self._increment_checked and self.step / self.rate_hz < 2 * gt_period * 0.99:  # 0.99: rates' digits
            warnings.warn(
                f"the shortest loss increment, {self.step} samples, spans {1e3 * self.step / self.rate_hz:.3g} ms at "
                f"{self.rate_hz:.4g} Hz, under two periods of the ground truth ({1e3 * gt_period:.3g} ms): the loss "
                "then mostly fits the truth's noise and interpolation. Lengthen loss.increments (powers of two)",
                consistency.DataConsistencyWarning,  # a project category: printed as one 'warning:' line
                stacklevel=1,
            )
        self._increment_checked = True
        checked = self._rates_warned
        for seq in [*self.val_part, *self.test_part]:
            if seq.name not in checked and abs(seq.rate_hz / self.rate_hz - 1.0) > RATE_TOL:
                warnings.warn(
                    f"{seq.name} samples at {seq.rate_hz:.4g} Hz, the training data at {self.rate_hz:.4g} Hz: its "
                    "figures measure the model off its rate (resample it, or train at its rate)",
                    consistency.DataConsistencyWarning,
                    stacklevel=1,
                )
            checked.add(seq.name)

    def normalization(self) -> tuple[np.ndarray, np.ndarray]:
        """Per-channel mean and std of the training IMU data (never validation or test)."""
        if not self.train_part:
            self.setup("fit")
        x = np.concatenate([s.imu for s in self.train_part])
        return x.mean(0), x.std(0) + 1e-8

    @property
    def rate_hz(self) -> float:
        seqs = self.train_part or self.test_part
        return float(np.median([s.rate_hz for s in seqs]))

    def train_dataloader(self) -> DataLoader:
        # the per-sample noise of a density depends on the rate: a nominal sensor.rate_hz far from the data's is not
        # used (within 5 % it is kept, so that runs reproduce: EuRoC measures 200.0026 Hz, TUM-VI 199.36)
        nominal, measured = self.sensor.get("rate_hz"), self.rate_hz
        if nominal is None or abs(measured / nominal - 1.0) > NOMINAL_RATE_TOL:
            if nominal is not None:
                counts = (
                    " The settings that count samples are set for 200 Hz: scale dataset.window, loss.increments and "
                    "model.dilations with the rate (docs/own-data.md, 'Rates other than 200 Hz')."
                    if abs(measured / 200.0 - 1.0) > NOMINAL_RATE_TOL
                    else ""
                )
                warnings.warn(
                    f"dataset.sensor.rate_hz={nominal:g}, but the training sequences are sampled at {measured:.1f} Hz: "
                    f"the augmentation noise uses {measured:.1f} Hz. Set dataset.sensor.rate_hz to your IMU's rate."
                    + counts,
                    consistency.DataConsistencyWarning,
                    stacklevel=1,  # this module, not Lightning's caller
                )
            self.augment = self._augment_config(measured)
        ds = RandomCrops(self.train_part, self.window, self.step, self.block, self.crops_per_epoch, self.augment)
        return DataLoader(ds, batch_size=len(self.train_part), shuffle=False, num_workers=0)

    def _whole(self, seqs: list[Sequence], groups: list[str] | None = None) -> DataLoader:
        items = [sequence_item(s, self.step, self.block) for s in seqs]
        for item, group in zip(items, groups or [], strict=False):
            item["group"] = group
        return DataLoader(items, batch_size=1, shuffle=False, collate_fn=_collate_one)

    def val_dataloader(self) -> DataLoader:
        return self._whole(self.val_part, self.val_groups)

    def test_dataloader(self) -> DataLoader:
        return self._whole(self.test_part)


def _collate_one(items: list[dict]) -> dict:
    (item,) = items
    return {k: (v.unsqueeze(0) if torch.is_tensor(v) else v) for k, v in item.items()}


def noise_std_from_density(density: float, rate_hz: float, scale: float = 0.5) -> float:
    """Per-sample std of white noise with a given density (unit/sqrt(Hz)), times `scale`."""
    return scale * density * math.sqrt(rate_hz)


def data_available(root: str | Path, names: list[str]) -> bool:
    return all((Path(root) / n / "mav0" / "imu0" / "data.csv").is_file() for n in names)
