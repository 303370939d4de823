"""The whole training step (forward, increment loss, backward, Adam) replayed as one captured CUDA graph.

One epoch of the EuRoC run is one optimiser step of ~470 small kernels; on a GPU, launching them from Python costs
three times what the GPU spends computing them (benchmarks/results/gpu_step_breakdown.md: 13.1 ms per step eager,
4.3 ms as one graph, GPU busy 4.4 ms). A captured graph launches them all at once. The arithmetic is the same
(Adam's `capturable` form of the same update; dropout masks from the same CUDA generator, drawn at each replay),
so results agree with the eager step to float rounding, not bit for bit (tests/test_cuda_graph_step.py on a GPU).

Capture needs static tensors: the batch is copied into buffers of the captured shape, the gradients are never set
to None, Adam's learning rate becomes a device tensor that the scheduler fills in place (torch's schedulers do),
and its state lives on the device. The warm-up steps that a capture needs run on a snapshot: parameters, buffers
(batch-norm statistics), Adam's state and the CUDA random state are put back afterwards (also when the warm-up is
interrupted), so the run takes the same steps as an eager one and a resumed run draws the masks the uninterrupted
one drew. A batch of another shape runs eagerly (with the same optimiser); `replays` and `eager_steps` count both.
"""

from __future__ import annotations

from collections.abc import Callable

import torch

WARMUP_STEPS = 2  # side-stream steps before the capture (lazy initialisation: cuDNN, Adam's state, allocator)
BATCH_KEYS = ("imu", "dt", "dR", "dR_mask")


def make_capturable(optimizer: torch.optim.Optimizer, device: torch.device) -> None:
    """Adam's capturable form, in place: learning rate a device tensor, step counters on the device."""
    for group in optimizer.param_groups:
        group["capturable"] = True
        if not isinstance(group["lr"], torch.Tensor):
            group["lr"] = torch.tensor(float(group["lr"]), device=device)
        for p in group["params"]:
            state = optimizer.state.get(p)
            if state and "step" in state:
                state["step"] = state["step"].to(device=device, dtype=torch.float32)


def device_neutral(checkpoint: dict) -> dict:
    """A checkpoint with the capturable settings undone in its optimiser states (plain float learning rates,
    capturable off) and its schedulers' (their last rates are copies of the tensor rates), so that a checkpoint
    written by a graph run resumes anywhere, the CPU included. In place; returns the checkpoint."""
    for state in checkpoint.get("optimizer_states", []):
        for group in state.get("param_groups", []):
            for key in ("lr", "initial_lr"):
                if isinstance(group.get(key), torch.Tensor):
                    group[key] = float(group[key])
            if "capturable" in group:
                group["capturable"] = False
    for state in checkpoint.get("lr_schedulers", []):
        for key, value in state.items():
            if isinstance(value, list) and any(isinstance(v, torch.Tensor) for v in value):
                state[key] = [float(v) if isinstance(v, torch.Tensor) else v for v in value]
    return checkpoint


class GraphedTrainingStep:
    """`step(batch) -> loss` for a module with `.model` and `.loss_fn`, replaying one CUDA graph per step."""

    def __init__(self, module: torch.nn.Module, optimizer: torch.optim.Optimizer) -> None:
        self.module, self.optimizer = module, optimizer
        self.graph: torch.cuda.CUDAGraph | None = None
        self.static: dict[str, torch.Tensor] = {}
        self.static_loss: torch.Tensor | None = None
        self.replays = self.eager_steps = 0

    def _step(self, batch: dict) -> torch.Tensor:
        """One eager step; also the body the graph captures."""
        self.optimizer.zero_grad(set_to_none=False)  # captured gradients keep their memory
        m = self.module
        loss = m.loss_fn(m.model(batch["imu"]), batch["dt"], batch["dR"], batch["dR_mask"])
        loss.backward()
        self.optimizer.step()
        return loss.detach()

    def _snapshot(self) -> Callable[[], None]:
        """A function that puts parameters, buffers and the optimiser's state back as they are now."""
        tensors = list(self.module.parameters()) + list(self.module.buffers())
        saved = [t.detach().clone() for t in tensors]
        had_state = {p: {k: v.clone() for k, v in s.items()} for p, s in self.optimizer.state.items()}
        device = tensors[0].device
        rng = torch.cuda.get_rng_state(device) if device.type == "cuda" else None

        def restore() -> None:
            if rng is not None:  # the dropout masks the warm-up drew are drawn again by the first replay
                torch.cuda.set_rng_state(rng, device)
            with torch.no_grad():
                for t, s in zip(tensors, saved, strict=True):
                    t.copy_(s)
                for p, state in self.optimizer.state.items():
                    for k, v in state.items():  # in place: the graph holds these tensors' memory
                        if isinstance(v, torch.Tensor):
                            v.copy_(had_state[p][k]) if p in had_state else v.zero_()

        return restore

    def _capture(self, batch: dict) -> None:
        device = batch["imu"].device
        make_capturable(self.optimizer, device)
        self.static = {k: batch[k].clone() for k in BATCH_KEYS}
        restore = self._snapshot()
        side = torch.cuda.Stream(device)
        side.wait_stream(torch.cuda.current_stream(device))
        try:
            with torch.cuda.stream(side):
                for _ in range(WARMUP_STEPS):
                    self._step(self.static)
        finally:  # an interruption inside the warm-up must not leave its steps in the weights a checkpoint saves
            torch.cuda.current_stream(device).wait_stream(side)
            restore()
        graph = torch.cuda.CUDAGraph()
        with torch.cuda.graph(graph):
            self.static_loss = self._step(self.static)
        self.graph = graph

    def __call__(self, batch: dict) -> torch.Tensor:
        if self.graph is None:
            self._capture(batch)  # records the step into the graph without running it; the replay below runs it
        elif any(batch[k].shape != self.static[k].shape for k in BATCH_KEYS):
            self.eager_steps += 1
            return self._step(batch)
        else:
            for k in BATCH_KEYS:
                self.static[k].copy_(batch[k], non_blocking=True)
        self.graph.replay()
        self.replays += 1
        return self.static_loss.clone()
