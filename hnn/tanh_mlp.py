"""The paper's tanh MLP in arithmetic: a faster tanh, and the closed-form input gradient
d(w . tanh(W2 tanh(W1 x + b1) + b2))/dx with its hand-written backward (``hnn.MLP`` uses both:
the tanh as its ``'tanh'`` nonlinearity, the gradient in ``MLP.input_gradient``).
"""
from __future__ import annotations

import numpy as np
import torch
from torch import nn

# torch.tanh costs about 2 ns an element on CPU (0.3 ms for a 750 x 200 float32 array, more than
# all the elementwise work of an HNN training step besides); 2 sigmoid(2a) - 1 is the same
# function in four cheap passes (0.06 ms), with at most 1.8e-7 absolute error in float32 against
# torch.tanh's 3e-8, below the rounding of the matrix products that read it (float64: 2e-16).
# Under this many elements the four dispatches cost more than tanh's arithmetic (measured: equal
# at 15 x 200), so small batches, e.g. an integrator's, keep torch.tanh.
_FAST_TANH_MIN_ELEMENTS = 4096


def _tanh_(a: torch.Tensor) -> torch.Tensor:
    """tanh of ``a``, in place (no autograd)."""
    if a.numel() < _FAST_TANH_MIN_ELEMENTS:
        return a.tanh_()
    return a.mul_(2).sigmoid_().mul_(2).sub_(1)


class _Tanh(torch.autograd.Function):
    """tanh by ``_tanh_``, with torch's own tanh backward (differentiable again, for double backprop)."""

    @staticmethod
    def forward(ctx, a):
        h = _tanh_(a.clone())
        ctx.save_for_backward(h)
        return h

    @staticmethod
    def backward(ctx, grad):
        h, = ctx.saved_tensors
        return torch.ops.aten.tanh_backward(grad, h)


def _tanh(a: torch.Tensor) -> torch.Tensor:
    """The MLPs' ``'tanh'``: ``torch.tanh`` for small inputs, ``2 sigmoid(2a) - 1`` for large ones."""
    if a.numel() < _FAST_TANH_MIN_ELEMENTS:
        return torch.tanh(a)
    if torch.is_grad_enabled() and a.requires_grad:
        return _Tanh.apply(a)
    return _tanh_(a.clone())



def _tanh_mlp_input_gradient(x, W1, b1, W2, b2, w, saved: bool = True):
    """dF/dx for F = w . tanh(W2 tanh(W1 x + b1) + b2), and (if ``saved``) what its backward needs."""
    h1 = _tanh_(nn.functional.linear(x, W1, b1))
    h2 = _tanh_(nn.functional.linear(h1, W2, b2))
    one = h1.new_ones(())
    s1 = torch.addcmul(one, h1, h1, value=-1)    # tanh' = 1 - tanh^2, in one pass
    s2 = torch.addcmul(one, h2, h2, value=-1)
    if saved:
        W2w = w[:, None] * W2                    # folds the output weights into W2 (no N x H broadcast)
        g_h1 = s2 @ W2w                          # dF/dh1
    else:                                        # evaluation, often a small batch: scale the rows instead
        W2w, g_h1 = None, (s2 * w) @ W2
    g_a1 = g_h1 * s1                             # dF/da1
    # MKL multiplies a tall matrix by a thin one (H x n, n = input_dim) 5x faster when the thin
    # one is column-major (750 x 200 @ 200 x 2: 24 vs 111 us)
    return g_a1 @ W1.T.contiguous().T, ((h1, h2, s1, s2, g_h1, g_a1, W2w) if saved else ())


# An integrator calls the field thousands of times on a few states (15 trials, or one). There
# torch's tanh is slow (7 us for 15 x 200; numpy's 0.9 us) and each small torch op costs 1-2 us
# of dispatch, so the elementwise work runs in numpy on the tensors' own memory, while the
# products stay in torch (MKL, torch's thread count): 15 x 2 float32 states, 45 vs 64 us a call.
# Large batches stay in torch, which parallelises its elementwise work.
_SMALL_BATCH_MAX_ROWS = 64
_SMALL_BATCH_DTYPES = (torch.float32, torch.float64)


def _small_batch_input_gradient(x, W1, b1, W2, b2, w) -> torch.Tensor:
    """``_tanh_mlp_input_gradient(..., saved=False)`` with its elementwise passes in numpy (no autograd)."""
    h1 = nn.functional.linear(x, W1, b1)
    n1 = np.tanh(h1.numpy(), out=h1.numpy())
    h2 = nn.functional.linear(h1, W2, b2)
    n2 = np.tanh(h2.numpy(), out=h2.numpy())
    n2 = np.subtract(1, np.multiply(n2, n2, out=n2), out=n2)      # s2 = 1 - h2^2
    n2 *= w.detach().numpy()
    g_a1 = h2 @ W2
    n3 = g_a1.numpy()
    n3 *= np.subtract(1, np.multiply(n1, n1, out=n1), out=n1)     # times s1 = 1 - h1^2
    return g_a1 @ W1


def _evaluation_input_gradient(x, W1, b1, W2, b2, w) -> torch.Tensor:
    """The closed form without autograd: numpy's elementwise passes for a few CPU states, else torch's."""
    if len(x) <= _SMALL_BATCH_MAX_ROWS and x.device.type == "cpu" and x.dtype in _SMALL_BATCH_DTYPES \
            and all(p.dtype == x.dtype and p.device == x.device for p in (W1, b1, W2, b2, w)):
        return _small_batch_input_gradient(x, W1, b1, W2, b2, w)
    return _tanh_mlp_input_gradient(x, W1, b1, W2, b2, w, saved=False)[0]


class _TanhMLPInputGradient(torch.autograd.Function):
    """d(out_k)/dx of a tanh ``MLP`` in closed form, with a hand-written backward.

    Numerically the same as ``autograd.grad(out[:, k].sum(), x, create_graph=True)``, but
    its backward does six large matrix products and a few in-place passes, where autograd's
    generic double backward allocates some twenty full-size temporaries: about 2x faster
    training on CPU. ``tests/test_models.py`` checks values and all gradients against autograd.
    """

    @staticmethod
    def forward(ctx, x, W1, b1, W2, b2, w):
        g_x, saved = _tanh_mlp_input_gradient(x, W1, b1, W2, b2, w)
        ctx.save_for_backward(x, W1, W2, w, *saved)
        return g_x

    @staticmethod
    @torch.autograd.function.once_differentiable
    def backward(ctx, d_gx):
        x, W1, W2, w, h1, h2, s1, s2, g_h1, g_a1, W2w = ctx.saved_tensors
        d_ga1 = d_gx @ W1.T
        d_gh1 = d_ga1 * s1
        d_W2w = s2.T @ d_gh1
        # tanh'' = -2 tanh tanh': the -2 rides on the small H x H matrix, not on an N x H pass
        d_a2 = (d_gh1 @ (-2 * W2w).T).mul_(h2).mul_(s2)
        d_W2 = torch.addmm(d_W2w * w[:, None], d_a2.T, h1)
        d_w = (d_W2w * W2).sum(1)
        # through s1 = 1 - h1^2 (the -2 folded into beta), plus through a2 = h1 W2^T
        d_h1 = torch.addmm(d_ga1.mul_(g_h1).mul_(h1), d_a2, W2, beta=-2)
        d_a1 = d_h1.mul_(s1)
        # as the transpose: MKL is 8x faster at a (n x N) @ (N x H) product than at (H x N) @ (N x n)
        d_W1 = torch.addmm(d_gx.T @ g_a1, x.T, d_a1).T
        d_x = d_a1 @ W1.T.contiguous().T if ctx.needs_input_grad[0] else None
        return d_x, d_W1, d_a1.sum(0), d_W2, d_a2.sum(0), d_w
