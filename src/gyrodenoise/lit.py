"""LightningModule: the correction model trained with the increment loss.

Hyperparameters are plain dicts and numbers only, so checkpoints reload under torch's
`weights_only` default. Validation integrates the corrected gyro over each whole validation
sequence (in float64, on the training device) and logs its AOE per validation group; figures go to
TensorBoard or MLflow when one of those loggers is active (gyrodenoise.run_loggers).
"""

from __future__ import annotations

import math
from concurrent.futures import Future, ThreadPoolExecutor

import lightning.pytorch as L
import numpy as np
import torch
from omegaconf import DictConfig, OmegaConf

from gyrodenoise import plots
from gyrodenoise.cli_errors import TrainingDiverged
from gyrodenoise.cuda_graph_step import GraphedTrainingStep, device_neutral
from gyrodenoise.losses import IncrementLoss
from gyrodenoise.metrics import aoe_torch, orientation_errors
from gyrodenoise.models.build import build_model
from gyrodenoise.run_loggers import log_figures, wants_figures
from gyrodenoise.so3 import integrate_gyro_torch

# Lightning hooks around the optimiser step: with the graph step, on_before_optimizer_step would not run and the
# others would run after Adam has stepped, so a callback (or subclass) that has one trains eagerly
STEP_HOOKS = ("on_before_zero_grad", "on_before_backward", "on_after_backward", "on_before_optimizer_step")
# what configure_optimizers reads (Adam and the schedule): the `optim` node's keys, and its `scheduler`'s (the cosine
# keys stay beside name: constant, from train.yaml's defaults)
OPTIM_KEYS = ("lr", "weight_decay", "cuda_graph", "scheduler")
SCHEDULER_KEYS = ("name", "T_0", "T_mult", "eta_min")


class DenoiserModule(L.LightningModule):
    def __init__(self, model: dict, optim: dict, loss: dict, figure_every_n_val: int = 5) -> None:
        super().__init__()
        self.save_hyperparameters()
        self.model = build_model(**model)
        self.loss_fn = IncrementLoss(**loss)
        self.figure_every_n_val = figure_every_n_val
        # the run's seed and data settings (train.resume_settings), written into checkpoints so that a resume with
        # others is refused as one with another model is (they are not hyperparameters of the module)
        self.run_settings: dict | None = None
        # validation figures are drawn in one background thread: ~1 s a set on a CPU core, and an 1800-epoch run
        # draws 8 sets, beside a fit of 22-26 s on an H200 (GPU call 8; the saving there not measured yet);
        # on_train_end waits for them
        self._figure_pool: ThreadPoolExecutor | None = None
        self._figure_jobs: list[Future] = []
        self._val_outputs: list[dict] = []
        self._val_count = 0
        self._raw: dict[tuple[str, str], tuple[torch.Tensor, float]] = {}  # (group, sequence): _raw_reference
        self._graph: GraphedTrainingStep | None = None  # the training step as one CUDA graph (on_fit_start)
        self.step_kind = "eager (not fitted yet)"
        # Lightning's model summary runs this through the model (eval mode, no_grad) to print the FLOPs of one
        # second of IMU at 200 Hz and the in/out shapes; without it the summary reads "0 FLOPs"
        self.example_input_array = torch.zeros(1, 200, 6)

    @classmethod
    def from_config(cls, cfg: DictConfig) -> DenoiserModule:
        """The module of a train config (its `model`, `optim` and `loss` nodes, resolved to plain containers)."""
        return cls(**{k: OmegaConf.to_container(cfg[k], resolve=True) for k in ("model", "optim", "loss")})

    def setup(self, stage: str) -> None:
        dm = getattr(self.trainer, "datamodule", None) if self._trainer is not None else None
        if stage == "fit" and dm is not None:
            mean, std = dm.normalization()  # training data only; a resumed checkpoint overrides
            self.model.set_normalization(mean, std)

    def forward(self, imu: torch.Tensor) -> torch.Tensor:
        return self.model(imu)

    def graph_step_refusal(self) -> str | None:
        """Why this fit does not replay its training step as one CUDA graph (None: it does). The graph replaces
        Lightning's zero_grad, backward and optimizer step, so whatever hooks into those runs eagerly."""
        from lightning.pytorch.callbacks import Callback, GradientAccumulationScheduler, WeightAveraging
        from lightning.pytorch.strategies import SingleDeviceStrategy
        from lightning.pytorch.utilities.model_helpers import is_overridden

        t = self._trainer
        if not self.hparams.optim.get("cuda_graph", True):
            return "optim.cuda_graph is false"
        if t is None or self.device.type != "cuda":
            return "not on a CUDA device"
        if t.world_size > 1 or not isinstance(t.strategy, SingleDeviceStrategy):
            return f"strategy {type(t.strategy).__name__} (one device only)"
        if t.accumulate_grad_batches != 1 or t.gradient_clip_val:
            return "gradient accumulation or clipping is set"
        if str(t.precision) not in ("32-true", "32"):
            return f"trainer.precision={t.precision}"
        if torch.is_anomaly_enabled():
            return "autograd anomaly detection is on"
        for cb in t.callbacks:
            if isinstance(cb, WeightAveraging | GradientAccumulationScheduler):
                return f"callback {type(cb).__name__} acts on the optimiser step"
            hooks = [h for h in STEP_HOOKS if is_overridden(h, cb, Callback)]
            if hooks:
                return f"callback {type(cb).__name__} hooks into the step ({', '.join(hooks)})"
        hooks = [h for h in STEP_HOOKS if is_overridden(h, self, L.LightningModule)]
        return f"the module hooks into the step ({', '.join(hooks)})" if hooks else None

    def on_fit_start(self) -> None:
        refusal = self.graph_step_refusal()
        self._graph = GraphedTrainingStep(self, self.trainer.optimizers[0]) if refusal is None else None
        # what summary.json records ("training_step"): how this fit stepped, and why not as a graph
        self.step_kind = "CUDA graph" if refusal is None else f"eager ({refusal})"

    def on_fit_end(self) -> None:
        if self._graph is not None and self._graph.eager_steps:  # batches of another shape than the first
            self.step_kind = f"CUDA graph ({self._graph.replays} replays, {self._graph.eager_steps} eager steps)"
        self._graph = None  # frees the graph's memory pool before the test

    def training_step(self, batch: dict, batch_idx: int) -> torch.Tensor:
        if self._graph is not None:  # forward, loss, backward and Adam in one replay (optimizer_step below)
            loss = self._graph(batch)
        else:
            w_hat = self.model(batch["imu"])
            loss = self.loss_fn(w_hat, batch["dt"], batch["dR"], batch["dR_mask"])
        logs = self._logs_this_step()
        # a non-finite loss is checked every step on the CPU (no device sync to save) and on the logging steps
        # elsewhere (the logged value is read back there anyway)
        if (logs or loss.device.type == "cpu") and not torch.isfinite(loss):
            self._diverged(f"train/loss is {float(loss.detach())}")
        if logs:
            self.log("train/loss", loss.float(), prog_bar=True, batch_size=batch["imu"].shape[0])
        return loss

    # With the graph step, the replay in training_step has already zeroed the gradients, back-propagated and
    # stepped Adam: Lightning's own calls of these three hooks do nothing then (its closure still runs
    # training_step, and its step counters advance as usual). Lightning's on_before_optimizer_step is then not
    # called and on_after_backward sees the weights after the step: fits that use them step eagerly (STEP_HOOKS).
    def optimizer_zero_grad(self, epoch: int, batch_idx: int, optimizer: torch.optim.Optimizer) -> None:
        if self._graph is None:
            super().optimizer_zero_grad(epoch, batch_idx, optimizer)

    def backward(self, loss: torch.Tensor, *args, **kwargs) -> None:
        if self._graph is None:
            super().backward(loss, *args, **kwargs)

    def optimizer_step(self, epoch: int, batch_idx: int, optimizer, optimizer_closure=None) -> None:
        if self._graph is None:
            super().optimizer_step(epoch, batch_idx, optimizer, optimizer_closure)
        elif optimizer_closure is not None:
            optimizer_closure()

    def _diverged(self, what: str) -> None:
        lr = self.hparams.optim.get("lr")
        raise TrainingDiverged(
            f"{what} at epoch {self.current_epoch + 1} (step {self.global_step}): the run diverged and was stopped; "
            f"no model.pt written. Lower optim.lr (now {lr}) or loss.weight, or check the data; the best validation "
            "checkpoint so far, if any, is in checkpoints/"
        )

    def _logs_this_step(self) -> bool:
        """Whether the loggers write this step (trainer.log_every_n_steps, and the last epoch for the progress
        bar). A logged loss is read back to the host at the step's end (the progress bar's number): on a GPU
        that waits for the step, so the other steps do not log it."""
        trainer = self._trainer
        if trainer is None:
            return True
        last = trainer.max_epochs is not None and self.current_epoch + 1 >= trainer.max_epochs
        return (self.global_step + 1) % trainer.log_every_n_steps == 0 or last

    @staticmethod
    def _integrate_and_score(batch: dict, gyro: torch.Tensor) -> tuple[torch.Tensor, tuple[float, float]]:
        """Open-loop attitude from `gyro` (N, 3) aligned at the first ground truth, and its AOE (3D, yaw)
        in rad; in float64 on the batch's device (no copy to the CPU during training)."""
        rot = batch["rot"][0]
        R_est = integrate_gyro_torch(rot[0], gyro, batch["dt"][0])
        return R_est, aoe_torch(rot, R_est, batch["gt_mask"][0])

    def _raw_reference(self, batch: dict) -> tuple[torch.Tensor, float]:
        """The raw IMU integrated like the model's output on this sequence, and its AOE (rad): the reference the
        correction has to beat, the same at every validation, so computed once per sequence."""
        key = (batch.get("group", "val"), batch["name"])
        if key not in self._raw:
            R_raw, (a3d, _) = self._integrate_and_score(batch, batch["imu"][0, :, :3])
            self._raw[key] = (R_raw, a3d)
        return self._raw[key]

    def _evaluate_sequence(self, batch: dict) -> dict:
        w_hat = self.model(batch["imu"])
        loss = self.loss_fn(w_hat, batch["dt"], batch["dR"], batch["dR_mask"])
        R_est, (a3d, ayaw) = self._integrate_and_score(batch, w_hat[0])
        return {
            "name": batch["name"],
            "group": batch.get("group", "val"),
            "loss": float(loss),
            "aoe": a3d,
            "raw_aoe": self._raw_reference(batch)[1],
            "aoe_yaw": ayaw,
            "batch": batch,
            "R_est": R_est,
            "w_hat": w_hat[0],
        }

    def validation_step(self, batch: dict, batch_idx: int) -> None:
        self._val_outputs.append(self._evaluate_sequence(batch))

    def on_validation_epoch_end(self) -> None:
        outs, self._val_outputs = self._val_outputs, []
        if not outs:
            return
        # one figure set per group: "val" (the selection protocol's sequences) and, in cross-validation,
        # "val_tail" (the rest of the training flights, the paper's validation) for comparison.
        # sync_dist: under DDP each process validates a share of the sequences; average the shares
        for group in dict.fromkeys(o["group"] for o in outs):
            g = [o for o in outs if o["group"] == group]
            self.log(f"{group}/loss", float(np.mean([o["loss"] for o in g])), sync_dist=True)
            aoe_deg = math.degrees(np.mean([o["aoe"] for o in g]))
            self.log(f"{group}/aoe_deg", aoe_deg, prog_bar=group == "val", sync_dist=True)
            self.log(f"{group}/aoe_yaw_deg", math.degrees(np.mean([o["aoe_yaw"] for o in g])), sync_dist=True)
            self.log(f"{group}/raw_imu_aoe_deg", math.degrees(np.mean([o["raw_aoe"] for o in g])), sync_dist=True)
            for o in g:  # each validation sequence (under DDP each process logs its own share: no sync)
                self.log(f"{group}/aoe_deg/{o['name']}", math.degrees(o["aoe"]))
        if not self.trainer.sanity_checking and not all(math.isfinite(o["aoe"]) for o in outs):
            bad = [o["name"] for o in outs if not math.isfinite(o["aoe"])]
            self._diverged(f"validation AOE is NaN/inf on {', '.join(bad)}")
        if not self.trainer.sanity_checking:
            self._val_count += 1
            last = self.trainer.max_epochs is not None and self.current_epoch + 1 >= self.trainer.max_epochs
            if self._val_count % self.figure_every_n_val == 1 or self.figure_every_n_val == 1 or last:
                self._log_figures(outs[0], "val")

    def test_step(self, batch: dict, batch_idx: int) -> None:
        o = self._evaluate_sequence(batch)
        self.log(f"test/aoe_deg/{o['name']}", math.degrees(o["aoe"]), batch_size=1)
        self.log(f"test/aoe_yaw_deg/{o['name']}", math.degrees(o["aoe_yaw"]), batch_size=1)
        self.log("test/aoe_deg", math.degrees(o["aoe"]), batch_size=1)  # averaged over sequences
        self.log("test/aoe_yaw_deg", math.degrees(o["aoe_yaw"]), batch_size=1)
        # reference: the raw IMU integrated the same way
        raw_3d = math.degrees(self._integrate_and_score(batch, batch["imu"][0, :, :3])[1][0])
        self.log(f"test/raw_imu_aoe_deg/{o['name']}", raw_3d, batch_size=1)
        self.log("test/raw_imu_aoe_deg", raw_3d, batch_size=1)

    def _log_figures(self, o: dict, prefix: str) -> None:
        if not wants_figures(self.loggers):
            return
        # the step of the scalars logged by this validation (Lightning's logger step), not global_step,
        # which is one ahead of it here: figures and curves of one validation share an x value
        step = getattr(self.trainer.fit_loop.epoch_loop, "_batches_that_stepped", self.global_step)
        of = f"/{self.trainer.max_epochs}" if self.trainer.max_epochs else ""
        title = (
            f"{o['name']}: AOE {math.degrees(o['aoe']):.2f} deg, yaw {math.degrees(o['aoe_yaw']):.2f} deg "
            f"(epoch {self.current_epoch + 1}{of})"
        )
        b = o["batch"]
        arrays = {  # copies on the host, taken now: training goes on while the figures are drawn
            "t": b["t"][0].cpu().numpy().copy(),
            "rot": b["rot"][0].cpu().numpy().copy(),
            "gt_mask": b["gt_mask"][0].cpu().numpy().copy(),
            "w_tilde": (o["w_hat"].double() - b["imu"][0, :, :3].double()).cpu().numpy(),
            # the raw IMU integrated the same way: the reference the correction has to beat
            "R_raw": self._raw_reference(b)[0].cpu().numpy().copy(),
            "R_est": o["R_est"].cpu().numpy().copy(),
        }
        if self._figure_pool is None:
            self._figure_pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="gyrodenoise-figures")
        job = self._figure_pool.submit(_draw_and_log, list(self.loggers), arrays, title, prefix, step)
        self._figure_jobs.append(job)

    def on_train_end(self) -> None:
        # before Lightning closes the loggers (after on_train_end): every figure set drawn and logged, a drawing
        # error raised here
        self.wait_for_figures()

    def on_validation_end(self) -> None:
        if self._trainer is not None and self.trainer.state.fn != "fit":  # trainer.validate(): no on_train_end
            self.wait_for_figures()

    def wait_for_figures(self) -> None:
        """Block until the figure sets handed to the drawing thread are logged (re-raises a drawing error), then
        end the thread (a module holding none can be copied and pickled)."""
        jobs, self._figure_jobs = self._figure_jobs, []
        try:
            for job in jobs:
                job.result()
        finally:
            if self._figure_pool is not None:
                self._figure_pool.shutdown()
                self._figure_pool = None

    def on_save_checkpoint(self, checkpoint: dict) -> None:
        # the random stream (crops, augmentation, dropout: all torch's generators) travels with the weights, so a
        # run resumed from last.ckpt continues on the uninterrupted run's path instead of a fresh draw
        checkpoint["rng_states"] = {"torch": torch.get_rng_state()}
        device_neutral(checkpoint)  # a graph run's checkpoint resumes anywhere
        if torch.cuda.is_available() and torch.cuda.is_initialized():
            checkpoint["rng_states"]["cuda"] = torch.cuda.get_rng_state_all()
        dm = getattr(self.trainer, "datamodule", None) if self._trainer is not None else None
        if dm is not None and hasattr(dm, "model_meta"):  # the data facts travel with a checkpoint copied elsewhere
            checkpoint["data_facts"] = dm.model_meta()
        if self.run_settings is not None:
            checkpoint["run_settings"] = self.run_settings

    def on_load_checkpoint(self, checkpoint: dict) -> None:
        states = checkpoint.get("rng_states")  # absent in checkpoints written before it was saved: resume as before
        if states is None:
            return
        torch.set_rng_state(states["torch"])
        if "cuda" in states and torch.cuda.is_available() and len(states["cuda"]) == torch.cuda.device_count():
            torch.cuda.set_rng_state_all(states["cuda"])

    def configure_optimizers(self):
        o = self.hparams.optim
        # a key nothing reads (+optim.betas=..., +optim.scheduler.gamma=...) was accepted and recorded as if used
        for node, keys, what in ((o, OPTIM_KEYS, "optimiser"), (o.get("scheduler") or {}, SCHEDULER_KEYS, "schedule")):
            if unknown := sorted(set(node) - set(keys)):
                where = "optim" if node is o else "optim.scheduler"
                raise ValueError(f"{where}.{unknown[0]} is not a setting of the {what}; it takes {', '.join(keys)}")
        opt = torch.optim.Adam(self.parameters(), lr=o["lr"], weight_decay=o.get("weight_decay", 0.0))
        sched = o.get("scheduler") or {"name": "constant"}
        if sched["name"] == "constant":  # a scheduler that changes nothing: the rate is logged under its name too
            s = torch.optim.lr_scheduler.ConstantLR(opt, factor=1.0, total_iters=0)
        elif sched["name"] == "cosine_warm_restarts":
            s = torch.optim.lr_scheduler.CosineAnnealingWarmRestarts(
                opt, T_0=sched["T_0"], T_mult=sched.get("T_mult", 1), eta_min=sched.get("eta_min", 0.0)
            )
        else:
            raise ValueError(f"optim.scheduler.name={sched['name']!r}; choose 'cosine_warm_restarts' or 'constant'")
        # "name": LearningRateMonitor's tag, beside train/loss (its default is the optimiser's class, "lr-Adam")
        return {"optimizer": opt, "lr_scheduler": {"scheduler": s, "interval": "epoch", "name": "train/lr"}}


def _draw_and_log(loggers: list, arrays: dict, title: str, prefix: str, step: int) -> None:
    """A validation's figure set (orientation, its error against the raw IMU's, the correction), drawn from host
    arrays and sent to `loggers` at `step`; runs in the module's drawing thread (matplotlib's Figure objects, no
    pyplot state)."""
    t, rot, gt_mask = arrays["t"], arrays["rot"], arrays["gt_mask"]
    R_est, R_raw = arrays["R_est"], arrays["R_raw"]
    errors = {"corrected": orientation_errors(rot, R_est), "raw IMU": orientation_errors(rot, R_raw)}
    figures = {
        f"{prefix}/orientation": plots.orientation_figure(t, rot, {"corrected": R_est}, title, gt_mask=gt_mask),
        f"{prefix}/orientation_error": plots.error_figure(t, errors, title, gt_mask),
        f"{prefix}/gyro_correction": plots.correction_figure(t, arrays["w_tilde"], title),
    }
    log_figures(loggers, figures, step)
