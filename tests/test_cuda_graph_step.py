"""The training step as one CUDA graph (gyrodenoise.cuda_graph_step): what it restores and writes is checked on the
CPU; that it computes what the eager step computes needs a CUDA device (those tests skip without one, saying so)."""

from __future__ import annotations

import copy
from types import SimpleNamespace

import pytest
import torch

from gyrodenoise.cuda_graph_step import GraphedTrainingStep, device_neutral, make_capturable
from gyrodenoise.lit import DenoiserModule

needs_cuda = pytest.mark.skipif(
    not torch.cuda.is_available(), reason="needs a CUDA device: CUDA graphs are captured and replayed on a GPU only"
)
MODEL = {"channels": [4, 8], "dilations": [1, 2], "dropout": 0.0}
OPTIM = {"lr": 0.01, "weight_decay": 0.1}


def module_and_batch(device: str = "cpu", n: int = 257, seed: int = 0) -> tuple[DenoiserModule, dict]:
    torch.manual_seed(seed)
    module = DenoiserModule(model=MODEL, optim=OPTIM, loss={}).to(device)
    with torch.no_grad():  # a head that is not zero, so that every layer gets a gradient from the first step
        module.model.net[-1].weight.normal_(0, 0.1)
    return module, random_batch(device, n, seed)


def random_batch(device: str, n: int = 257, seed: int = 0) -> dict:
    from gyrodenoise import so3

    g = torch.Generator().manual_seed(seed)
    imu = torch.randn(2, n, 6, generator=g)
    imu[..., 3:] += torch.tensor([0.0, 0.0, 9.81])
    blocks = (n - 1) // 16
    dR = so3.exp(0.01 * torch.randn(2, blocks, 3, generator=g, dtype=torch.float64))
    batch = {"imu": imu, "dt": torch.full((2, n), 0.005, dtype=torch.float64), "dR": dR}
    batch["dR_mask"] = torch.ones(2, blocks, dtype=torch.bool)
    return {k: v.to(device) for k, v in batch.items()}


def adam(module: DenoiserModule) -> torch.optim.Adam:
    return torch.optim.Adam(module.parameters(), lr=OPTIM["lr"], weight_decay=OPTIM["weight_decay"])


def eager_step(module: DenoiserModule, opt: torch.optim.Optimizer, batch: dict) -> None:
    opt.zero_grad()
    module.loss_fn(module.model(batch["imu"]), batch["dt"], batch["dR"], batch["dR_mask"]).backward()
    opt.step()


def test_the_snapshot_puts_weights_statistics_and_adam_back_and_a_zeroed_adam_is_a_fresh_one():
    module, batch = module_and_batch()
    opt = adam(module)
    fresh = copy.deepcopy(module)
    restore = GraphedTrainingStep(module, opt)._snapshot()  # Adam has no state yet
    for _ in range(2):
        eager_step(module, opt, batch)
    restore()
    for (name, a), b in zip(module.state_dict().items(), fresh.state_dict().values(), strict=True):
        torch.testing.assert_close(a, b, rtol=0, atol=0, msg=name)  # batch-norm statistics and counters too
    assert all(float(s["step"]) == 0 for s in opt.state.values())
    # Adam's zeroed state steps exactly as a new Adam does
    fresh_opt = adam(fresh)
    eager_step(module, opt, batch)
    eager_step(fresh, fresh_opt, batch)
    for (name, a), b in zip(module.state_dict().items(), fresh.state_dict().values(), strict=True):
        torch.testing.assert_close(a, b, rtol=0, atol=0, msg=name)
    # with state: put back to the values it had at the snapshot
    before = {k: v.clone() for k, v in opt.state[next(module.parameters())].items()}
    restore = GraphedTrainingStep(module, opt)._snapshot()
    eager_step(module, opt, batch)
    restore()
    for k, v in opt.state[next(module.parameters())].items():
        torch.testing.assert_close(v, before[k], rtol=0, atol=0, msg=k)


def test_a_graph_runs_checkpoint_resumes_anywhere():
    module, _ = module_and_batch()
    opt = adam(module)
    make_capturable(opt, torch.device("cpu"))
    assert isinstance(opt.param_groups[0]["lr"], torch.Tensor) and opt.param_groups[0]["capturable"]
    sched = torch.optim.lr_scheduler.CosineAnnealingWarmRestarts(opt, T_0=3, eta_min=1e-3)
    state = opt.state_dict()
    assert isinstance(sched.state_dict()["_last_lr"][0], torch.Tensor)
    checkpoint = device_neutral({"optimizer_states": [state], "lr_schedulers": [sched.state_dict()]})
    assert type(checkpoint["lr_schedulers"][0]["_last_lr"][0]) is float
    group = checkpoint["optimizer_states"][0]["param_groups"][0]
    # a float32 device tensor held the rate: equal to float32 rounding
    assert type(group["lr"]) is float and group["lr"] == pytest.approx(0.01, rel=1e-7)
    assert group["initial_lr"] == pytest.approx(0.01, rel=1e-7)
    assert group["capturable"] is False
    assert isinstance(opt.param_groups[0]["lr"], torch.Tensor)  # the optimiser itself is left as it was


def test_the_graph_step_says_why_it_is_off(monkeypatch):
    from lightning.pytorch.callbacks import Callback, GradientAccumulationScheduler
    from lightning.pytorch.strategies import DDPStrategy, SingleDeviceStrategy

    module, _ = module_and_batch()
    trainer = SimpleNamespace(world_size=1, accumulate_grad_batches=1, gradient_clip_val=None, precision="32-true")
    trainer.strategy, trainer.callbacks = SingleDeviceStrategy(device="cpu"), []
    module._trainer = trainer
    assert module.graph_step_refusal() == "not on a CUDA device"
    module._device = torch.device("cuda", 0)  # what a GPU fit sees (nothing here runs on it)
    assert module.graph_step_refusal() is None

    class GradientWatcher(Callback):
        def on_after_backward(self, trainer, pl_module) -> None:
            pass

    trainer.callbacks = [GradientWatcher()]
    assert module.graph_step_refusal() == "callback GradientWatcher hooks into the step (on_after_backward)"
    trainer.callbacks = [GradientAccumulationScheduler({0: 1})]
    assert "GradientAccumulationScheduler" in module.graph_step_refusal()
    trainer.callbacks = []
    with torch.autograd.set_detect_anomaly(True):
        assert module.graph_step_refusal() == "autograd anomaly detection is on"
    trainer.strategy = DDPStrategy()
    assert module.graph_step_refusal() == "strategy DDPStrategy (one device only)"
    module.hparams.optim["cuda_graph"] = False
    assert module.graph_step_refusal() == "optim.cuda_graph is false"


@needs_cuda
def test_the_graph_step_computes_what_the_eager_step_computes():
    eager, _ = module_and_batch("cuda")
    graphed = copy.deepcopy(eager)
    opt_e, opt_g = adam(eager), adam(graphed)
    sched_e = torch.optim.lr_scheduler.CosineAnnealingWarmRestarts(opt_e, T_0=3, eta_min=1e-3)
    sched_g = torch.optim.lr_scheduler.CosineAnnealingWarmRestarts(opt_g, T_0=3, eta_min=1e-3)
    step = GraphedTrainingStep(graphed, opt_g)
    for k in range(6):  # a new batch each step, copied into the captured buffers; the rate changes in place
        batch = random_batch("cuda", seed=k)
        eager_step(eager, opt_e, batch)
        loss = step(batch)
        assert loss.shape == () and torch.isfinite(loss)
        sched_e.step()
        sched_g.step()
    assert isinstance(opt_g.param_groups[0]["lr"], torch.Tensor)
    assert float(opt_g.param_groups[0]["lr"]) == pytest.approx(opt_e.param_groups[0]["lr"])
    for (name, a), b in zip(graphed.state_dict().items(), eager.state_dict().values(), strict=True):
        torch.testing.assert_close(a, b, rtol=1e-4, atol=1e-5, msg=name)
    # a batch of another shape runs eagerly with the same optimiser
    step(random_batch("cuda", n=129, seed=9))
    assert step.static["imu"].shape[1] == 257


@needs_cuda
def test_a_gpu_training_with_the_graph_ends_where_the_eager_one_does(tiny_asl_root, tmp_path):
    from test_train import config

    from gyrodenoise.train import train

    def run(out: str, *extra: str) -> dict:
        cfg = config(tiny_asl_root, tmp_path / out, "seed=2", "trainer.accelerator=gpu", "model.dropout=0.0", *extra)
        cfg.trainer.max_epochs = 6
        cfg.callbacks.last_checkpoint.every_n_epochs = 1
        summary = train(cfg)
        return summary, torch.load(tmp_path / out / "model.pt", weights_only=True)["state_dict"]

    graph_summary, graphed = run("graph")
    eager_summary, eager = run("eager", "optim.cuda_graph=false")
    assert graph_summary["epochs"] == eager_summary["epochs"] == 6
    assert graph_summary["training_step"] == "CUDA graph"
    assert eager_summary["training_step"] == "eager (optim.cuda_graph is false)"
    for name, a in graphed.items():  # Adam's steps are ~lr (1e-2): float rounding stays far below
        torch.testing.assert_close(a, eager[name], rtol=1e-3, atol=1e-4, msg=name)
    assert "eager steps" not in graph_summary["training_step"]  # every step was a replay
    # its last.ckpt resumes on the CPU (the capturable settings are not saved)
    last = tmp_path / "graph" / "checkpoints" / "last.ckpt"
    cpu = config(tiny_asl_root, tmp_path / "cpu", "seed=2", "trainer.max_epochs=7", f"ckpt_path={last}")
    assert train(cpu)["epochs"] == 7


@needs_cuda
def test_a_resumed_gpu_run_with_dropout_ends_on_the_uninterrupted_runs_weights(tiny_asl_root, tmp_path):
    """The capture's warm-up draws dropout masks; the CUDA random state is put back, so a run resumed from its
    last.ckpt (a second capture) draws what the uninterrupted run drew."""
    from test_train import config

    from gyrodenoise.train import train

    def run(out: str, epochs: int, *extra: str) -> dict:
        cfg = config(tiny_asl_root, tmp_path / out, "seed=5", "trainer.accelerator=gpu", "model.dropout=0.1", *extra)
        cfg.trainer.max_epochs = epochs
        cfg.optim.scheduler.T_0 = 4
        cfg.callbacks.last_checkpoint.every_n_epochs = 1
        assert train(cfg)["training_step"] == "CUDA graph"
        return torch.load(tmp_path / out / "model.pt", weights_only=True)["state_dict"]

    whole = run("whole", 4)
    run("part", 2)
    resumed = run("resumed", 4, f"ckpt_path={tmp_path / 'part' / 'checkpoints' / 'last.ckpt'}")
    for name, a in whole.items():
        torch.testing.assert_close(resumed[name], a, rtol=1e-5, atol=1e-6, msg=name)


@needs_cuda
def test_with_dropout_a_graph_run_draws_the_eager_runs_masks(tiny_asl_root, tmp_path):
    """Dropout masks come from the CUDA generator in both steps: a seed's graph run should draw what its eager run
    draws (the capture's warm-up state is put back), and so end on the same weights to float rounding."""
    from test_train import config

    from gyrodenoise.train import train

    def run(out: str, *extra: str) -> dict:
        cfg = config(tiny_asl_root, tmp_path / out, "seed=3", "trainer.accelerator=gpu", "model.dropout=0.1", *extra)
        cfg.trainer.max_epochs = 6
        train(cfg)
        return torch.load(tmp_path / out / "model.pt", weights_only=True)["state_dict"]

    graphed, eager = run("graph"), run("eager", "optim.cuda_graph=false")
    for name, a in graphed.items():
        torch.testing.assert_close(a, eager[name], rtol=1e-3, atol=1e-4, msg=name)
