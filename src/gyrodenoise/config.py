"""The project's Hydra configs composed from Python (benchmarks, tests, notebooks).

The same files and defaults as the command lines (`python -m gyrodenoise.train ...`), without running a
Hydra app: `compose_config("train", ["dataset=euroc", "seed=3"])` is the config that
`python -m gyrodenoise.train dataset=euroc seed=3` would run (minus the `hydra` node).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from hydra import compose, initialize_config_dir
from omegaconf import DictConfig

CONF_DIR = Path(__file__).parent / "conf"


def compose_config(name: str = "train", overrides: Sequence[str] = ()) -> DictConfig:
    """Config `name` (train, evaluate, fit_calibrated) of gyrodenoise/conf with Hydra `overrides` applied."""
    with initialize_config_dir(str(CONF_DIR), version_base="1.3"):
        return compose(name, overrides=list(overrides))
