"""What a run sends to its experiment loggers beyond Lightning's curves: figures, its settings beside its final
figures, and its output files.

TensorBoard (`logger=tensorboard`, the default) gets the figures as images and the hparams view; MLflow
(`logger=mlflow`, `pip install ".[mlflow]"`) gets the figures and the run's files (summary.json, model.pt,
calibrated.pt, train.log) as artifacts, the run's data settings as params (the module's model, optim and loss
settings are logged by Lightning at the start) and the kept model's validation figures as `selected_val/...`. The
CSV logger takes curves only.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from lightning.pytorch.loggers import Logger, MLFlowLogger, TensorBoardLogger
from matplotlib.figure import Figure

RUN_FILES = ("summary.json", "model.pt", "calibrated.pt", "train.log")


class MLflowRunLogger(MLFlowLogger):
    """Lightning's MLFlowLogger with metric names its file store can hold: that store makes each `/` a folder, so
    `test/aoe_deg` (a file) and `test/aoe_deg/MH_02_easy` (inside a folder of the same name) cannot both exist.
    Past the group (`test/`), `/` becomes `.`: `test/aoe_deg.MH_02_easy`.

    A cross-validation fold's run is named with its fold (`fold`: `denoiser-seed0-fold2`). A run resumed in its own
    folder (auto_resume, a requeued job) goes on in the MLflow run of that folder that did not finish (tag
    `output_dir`), so its curves stay one run, instead of a second run starting mid-way."""

    def __init__(self, *, fold: int | None = None, **kwargs: Any) -> None:
        if fold is not None and kwargs.get("run_name"):
            kwargs["run_name"] = f"{kwargs['run_name']}-fold{fold}"
        super().__init__(**kwargs)
        if self._run_id is None:  # Lightning would look the experiment up, and create it, unguarded
            self._experiment_id = _experiment_id(self._mlflow_client, self._tracking_uri, self._experiment_name)
            if folder := (self.tags or {}).get("output_dir"):
                self._run_id = _unfinished_run(self._mlflow_client, self._experiment_id, str(folder))

    def log_metrics(self, metrics: dict[str, float], step: int | None = None) -> None:
        # a tensor value (the CUDA-graph step's learning rate is a device tensor) as a plain number, for any store
        plain = {k: float(v) if hasattr(v, "item") else v for k, v in metrics.items()}
        super().log_metrics({mlflow_metric_name(k): v for k, v in plain.items()}, step)


def _experiment_id(client: Any, uri: str, name: str) -> str:
    """The experiment's id, created if new. Sweep jobs started together (the joblib launcher) would each find no
    experiment and create one: MLflow's file store then holds several of one name, the runs split among them. In a
    file store the lookup and creation hold a lock file; another store refuses a second creation, then looked up."""
    from filelock import FileLock  # a dependency of torch's
    from mlflow.exceptions import MlflowException

    def find_or_create() -> str:
        found = client.get_experiment_by_name(name)
        if found is not None:
            return found.experiment_id
        try:
            return client.create_experiment(name)
        except MlflowException:  # created by another job meanwhile (a server's or a database's store)
            return client.get_experiment_by_name(name).experiment_id

    if not uri.startswith("file:"):
        return find_or_create()
    store = Path(uri.removeprefix("file:").removeprefix("//"))
    store.mkdir(parents=True, exist_ok=True)
    with FileLock(store / ".gyrodenoise-experiments.lock"):
        return find_or_create()


def _unfinished_run(client: Any, experiment_id: str, folder: str) -> str | None:
    """The id of the newest run of the experiment that logged `folder` and did not finish (None: none)."""
    quoted = folder.replace("'", "\\'")
    runs = client.search_runs(
        [experiment_id],
        filter_string=f"tags.output_dir = '{quoted}' and attributes.status != 'FINISHED'",
        order_by=["attributes.start_time DESC"],
        max_results=1,
    )
    return runs[0].info.run_id if runs else None


_TAIL = re.compile(r"\[([0-9.]+)s:\]$")  # a training sequence's validation tail, NAME[Ns:]
_NOT_MLFLOW = re.compile(r"[^a-zA-Z0-9_/. -]")  # what Lightning's MLFlowLogger strips from a name, with a warning


def mlflow_metric_name(name: str) -> str:
    """`group/metric/sequence` -> `group/metric.sequence` (the names MLflow's file store can hold side by side). A
    validation tail `NAME[Ns:]` becomes `NAME_afterNs`, and other characters MLflow refuses `_` (Lightning stripped
    them, with a warning per name: `MH_01_easy[50s:]` read `MH_01_easy50s`)."""
    group, sep, rest = name.partition("/")
    rest = _TAIL.sub(r"_after\1s", rest.replace("/", "."))
    return _NOT_MLFLOW.sub("_", f"{group}{sep}{rest}")


def log_figures(loggers: Sequence[Logger], figures: dict[str, Figure], step: int) -> None:
    """`figures` (tag -> Figure) at `step`: TensorBoard images, MLflow artifacts `figures/<tag>/step<step>.png`."""
    for logger in loggers:
        if isinstance(logger, TensorBoardLogger):
            for tag, fig in figures.items():
                logger.experiment.add_figure(tag, fig, step, close=False)
        elif isinstance(logger, MLFlowLogger):
            for tag, fig in figures.items():
                logger.experiment.log_figure(logger.run_id, fig, f"figures/{tag}/step{step:07d}.png")


def wants_figures(loggers: Sequence[Logger]) -> bool:
    """Whether any logger takes figures (drawing them costs a validation's time otherwise spent on nothing)."""
    return any(isinstance(lg, TensorBoardLogger | MLFlowLogger) for lg in loggers)


def log_run_end(loggers: Sequence[Logger], hparams: dict[str, Any], metrics: dict[str, float], out_dir: Path) -> None:
    """The run's settings beside its final figures (`metrics`: val/..., test/...), and its files."""
    for logger in loggers:
        if isinstance(logger, TensorBoardLogger):  # hparams view: settings next to final val/test AOE
            # under hparams/...: Lightning writes these metrics at step 0, which under their own names
            # (val/aoe_deg, test/aoe_deg) would add a point at step 0 to the curves
            logger.log_hyperparams(hparams, {f"hparams/{k}": v for k, v in metrics.items()})
            logger.experiment.flush()  # on disk now, not when the writer's thread next flushes (a reader could miss it)
        elif isinstance(logger, MLFlowLogger):
            # the model/optim/loss settings are already params (Lightning logged the module's at the start, as
            # model/..., optim/...); MLflow refuses a param logged twice with another value, so only the others,
            # named as Lightning names those (dataset/window, not dataset.window; the dataset's name as dataset/name:
            # a file store keeps a param as a file, and dataset/... needs `dataset` to be a folder)
            logger.log_hyperparams(
                {
                    ("dataset/name" if k == "dataset" else k.replace(".", "/")): v
                    for k, v in hparams.items()
                    if k.split(".")[0] not in ("model", "optim", "loss")
                }
            )
            # the kept model's validation figures (select=best_val: not the curve's last point) beside test/...
            logger.log_metrics({f"selected_{k}": v for k, v in metrics.items() if k.startswith("val")})
            for name in RUN_FILES:
                if (out_dir / name).is_file():
                    logger.experiment.log_artifact(logger.run_id, str(out_dir / name))
