"""Drop-in layers of the denoiser that train faster on the CPU: same parameters, the same computation
to float32 rounding (the dropout: masks of the same distribution, from another generator).

Both are subclasses of their torch layer (state_dicts, `isinstance` checks, the streaming corrector
and exported graphs see nn.Conv1d / nn.Dropout) and behave as it does on other devices.
Measured in benchmarks/results/cpu_step_profile.md.
"""

from __future__ import annotations

import numpy as np
import torch
from torch import nn
from torch.nn import functional as F


class FastDropout(nn.Dropout):
    """nn.Dropout with a cheaper mask on the CPU: same expectation, p rounded to a multiple of 2^-15.

    On the CPU, torch's Bernoulli sampling costs ~10 ns per element, a fifth of a training step of
    this network (measured: 112 ms -> 29 ms forward + backward for a 7.8M-element activation).
    Here each 64-bit word of numpy's SFC64 generator (twice as fast as torch's Mersenne twister for
    the bits; seeded from torch's generator at every call, so `seed_everything` fixes the masks)
    gives four 16-bit lanes, and the low 15 bits of each lane are compared with p * 2^15. On other
    devices (fused dropout kernels) and inside torch.compile it is nn.Dropout.
    """

    LEVELS = 1 << 15

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        if (
            not self.training
            or self.p == 0.0
            or x.device.type != "cpu"
            or self.inplace
            or torch.compiler.is_compiling()
        ):
            return super().forward(x)  # torch.compile: numpy cannot be traced, the compiler fuses torch's own
        drop = round(self.p * self.LEVELS)
        if drop >= self.LEVELS:
            return torch.zeros_like(x)
        n = x.numel()
        seed = int(torch.randint(0, 2**62, ()))
        words = torch.from_numpy(np.random.SFC64(seed).random_raw((n + 3) // 4).view(np.int64))
        lanes = words.view(torch.int16)[:n].view(x.shape) & (self.LEVELS - 1)
        return x * ((lanes >= drop) * (self.LEVELS / (self.LEVELS - drop)))


class _InputGradAsConv(torch.autograd.Function):
    """conv1d (stride 1, no padding) whose input gradient is a forward convolution with the flipped,
    transposed kernel over the zero-padded output gradient; the weight and bias gradients are torch's."""

    @staticmethod
    def forward(ctx, x: torch.Tensor, weight: torch.Tensor, bias: torch.Tensor | None, dilation: int):
        ctx.save_for_backward(x, weight)
        ctx.dilation, ctx.has_bias = dilation, bias is not None
        return F.conv1d(x, weight, bias, dilation=dilation)

    @staticmethod
    def backward(ctx, grad: torch.Tensor):
        x, weight = ctx.saved_tensors
        pad = (weight.shape[-1] - 1) * ctx.dilation
        grad_x = grad_w = grad_b = None
        if ctx.needs_input_grad[0]:
            kernel = weight.flip(-1).transpose(0, 1)
            grad_x = F.conv1d(F.pad(grad, (pad, pad)), kernel, dilation=ctx.dilation)
        if ctx.needs_input_grad[1] or ctx.needs_input_grad[2]:
            _, grad_w, grad_b = torch.ops.aten.convolution_backward(
                grad,
                x,
                weight,
                [weight.shape[0]],
                [1],
                [0],
                [ctx.dilation],
                False,
                [0],
                1,
                [False, True, ctx.has_bias],
            )
        return grad_x, grad_w, grad_b, None


class DilatedConv1d(nn.Conv1d):
    """nn.Conv1d whose input gradient, on the CPU, is computed as a forward convolution.

    oneDNN's backward-data pass of dilated 1D convolutions is slow on this network (layer 2 and 3:
    about twice its forward time); a forward convolution with the flipped kernel gives the same
    gradient (to float32 rounding) ~8% faster per training step. Only for the stride-1, unpadded,
    ungrouped convolutions of the denoiser; otherwise, off the CPU, without gradients, under autocast or
    while torch.export / torch.compile trace, it is nn.Conv1d.
    """

    input_grad_as_conv = True  # False: torch's backward (benchmarks/cpu_step_profile.py compares)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        plain = self.stride != (1,) or self.padding != (0,) or self.groups != 1 or self.padding_mode != "zeros"
        if (
            plain
            or not self.input_grad_as_conv
            or x.device.type != "cpu"
            or not torch.is_grad_enabled()
            or torch.compiler.is_compiling()
            or torch.is_autocast_enabled("cpu")  # mixed precision: its backward would mix bf16 and float32
        ):
            return super().forward(x)
        return _InputGradAsConv.apply(x, self.weight, self.bias, self.dilation[0])
