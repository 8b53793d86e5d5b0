"""The paper's networks: the MLP and the Hamiltonian Neural Network built on it.

State convention: ``x = [q, p]`` of shape ``(batch, 2n)``; the first half is the
position half, the second half the momentum half.
"""
from __future__ import annotations

import warnings

import numpy as np
import torch
from torch import nn

from .integrate import rk4_step

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


_NONLINEARITIES = {
    "tanh": _tanh,
    "relu": torch.relu,
    "sigmoid": torch.sigmoid,
    "softplus": nn.functional.softplus,
    "selu": nn.functional.selu,
    "elu": nn.functional.elu,
    "swish": lambda x: x * torch.sigmoid(x),
}
NONLINEARITIES = tuple(_NONLINEARITIES)   # the names get_nonlinearity knows, for --nonlinearity choices
# Piecewise-linear activations: their second derivative is zero almost everywhere, so the
# symplectic gradient of an HNN built on them is piecewise constant in x and the training
# signal through d(dH/dx)/dtheta is poor.
_PIECEWISE_LINEAR = {"relu"}
FIELD_TYPES = ("solenoidal", "conservative", "both")


def get_nonlinearity(name: str):
    """The activation function called ``name`` (one of ``tanh relu sigmoid softplus selu elu swish``)."""
    try:
        return _NONLINEARITIES[name]
    except KeyError:
        raise ValueError(
            f"unknown nonlinearity {name!r}; choose one of {sorted(_NONLINEARITIES)}"
        ) from None


class MLP(nn.Module):
    """Two hidden layers and a linear output layer without bias, orthogonal init (the paper's net).

    Maps ``(batch, input_dim)`` to ``(batch, output_dim)``.
    """

    def __init__(self, input_dim: int, hidden_dim: int, output_dim: int, nonlinearity: str = "tanh"):
        super().__init__()
        for label, value in (("input_dim", input_dim), ("hidden_dim", hidden_dim), ("output_dim", output_dim)):
            if not isinstance(value, int) or value < 1:
                raise ValueError(f"MLP {label} must be a positive integer, got {value!r}")
        self.nonlinearity_name = nonlinearity
        self._act = get_nonlinearity(nonlinearity)
        self.input_dim, self.output_dim = input_dim, output_dim
        self.linear1 = nn.Linear(input_dim, hidden_dim)
        self.linear2 = nn.Linear(hidden_dim, hidden_dim)
        self.linear3 = nn.Linear(hidden_dim, output_dim, bias=False)
        for layer in (self.linear1, self.linear2, self.linear3):
            nn.init.orthogonal_(layer.weight)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        # _tanh_mlp_input_gradient differentiates this function by hand: edit both together
        # (tests/test_models.py compares the two)
        h = self._act(self.linear1(x))
        h = self._act(self.linear2(h))
        return self.linear3(h)

    def input_gradient(self, x: torch.Tensor, k: int, create_graph: bool) -> torch.Tensor:
        """d(self(x)[:, k])/dx, ``(batch, input_dim)``: in closed form when ``_closed_form_applies``
        (about 2x faster training), else by autograd; with ``create_graph`` it can be differentiated."""
        if not self._closed_form_applies():
            return _autograd_input_gradient(self, x, k, create_graph)
        l1, l2 = self.linear1, self.linear2
        params = (l1.weight, l1.bias, l2.weight, l2.bias, self.linear3.weight[k])
        if not torch.is_grad_enabled():     # evaluation: skip the autograd node (~0.1 ms a call)
            if len(x) <= _SMALL_BATCH_MAX_ROWS and x.device.type == "cpu" and x.dtype in _SMALL_BATCH_DTYPES \
                    and all(p.dtype == x.dtype and p.device == x.device for p in params):
                return _small_batch_input_gradient(x, *params)
            return _tanh_mlp_input_gradient(x, *params, saved=False)[0]
        return _TanhMLPInputGradient.apply(x, *params)

    def _closed_form_applies(self) -> bool:
        """Whether ``self(x)`` is the network the closed form differentiates: ``MLP.forward`` as
        defined above (not overridden by a subclass, nor replaced on the class or the instance
        since), tanh, plain linear layers and no forward hooks. Anything else gets autograd."""
        return (type(self).forward is _CLOSED_FORM_FORWARD and "forward" not in vars(self)
                and self._act is _tanh and not (self._forward_hooks or self._forward_pre_hooks)
                and all(type(layer) is nn.Linear for layer in (self.linear1, self.linear2, self.linear3)))


# the forward the closed form was written for, taken at import: a forward patched in later differs
_CLOSED_FORM_FORWARD = MLP.forward


def permutation_tensor(n: int, assume_canonical_coords: bool = True) -> torch.Tensor:
    """The ``(n, n)`` matrix M with ``dx/dt = grad H @ M.T``.

    Canonical coordinates give ``M = [[0, I], [-I, 0]]`` (Hamilton's equations). The other
    choice is the original code's Levi-Civita-like sign pattern, kept for parity; it equals the
    canonical one for n = 2 and is not symplectic in general.
    """
    if assume_canonical_coords:
        eye = torch.eye(n)
        return torch.cat([eye[n // 2:], -eye[: n // 2]])
    m = torch.ones(n, n)
    m *= 1 - torch.eye(n)
    m[::2] *= -1
    m[:, ::2] *= -1
    for i in range(n):
        for j in range(i + 1, n):
            m[i, j] *= -1
    return m


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


def _input_gradient(model: nn.Module, x: torch.Tensor, k: int, create_graph: bool) -> torch.Tensor:
    """d(model(x)[:, k])/dx, ``(batch, input_dim)``: an ``MLP`` computes its own (closed form when
    it applies), any other network goes through autograd."""
    if isinstance(model, MLP):
        return model.input_gradient(x, k, create_graph)
    return _autograd_input_gradient(model, x, k, create_graph)


def _autograd_input_gradient(model: nn.Module, x: torch.Tensor, k: int, create_graph: bool) -> torch.Tensor:
    """d(model(x)[:, k])/dx by autograd, ``(batch, input_dim)``; ``model`` must output ``(batch, 2)``."""
    with torch.enable_grad():
        x_in = x if (create_graph and x.requires_grad) else x.detach().requires_grad_(True)
        out = model(x_in)
        if out.dim() != 2 or out.shape[1] != 2:
            raise ValueError(f"an HNN's network must output (batch, 2) = (F1, F2), got {tuple(out.shape)}")
        return torch.autograd.grad(out[:, k].sum(), x_in, create_graph=create_graph)[0]


class HNN(nn.Module):
    """Hamiltonian Neural Network (Greydanus et al. 2019).

    ``differentiable_model`` maps ``(batch, input_dim)`` to two scalar fields ``(F1, F2)``
    (shape ``(batch, 2)``), or, with ``baseline=True``, directly to ``dx/dt`` of shape
    ``(batch, input_dim)``. ``time_derivative`` builds the vector field from the autograd
    gradient: the solenoidal part ``grad F2 @ M.T`` (Hamilton's equations with H = F2), the
    conservative part ``grad F1``, or both.
    """

    def __init__(self, input_dim: int, differentiable_model: nn.Module, field_type: str = "solenoidal",
                 baseline: bool = False, assume_canonical_coords: bool = True):
        super().__init__()
        if field_type not in FIELD_TYPES:
            raise ValueError(f"unknown field_type {field_type!r}; choose one of {FIELD_TYPES}")
        if not baseline and input_dim % 2:
            raise ValueError(f"an HNN needs an even input_dim (x = [q, p]), got {input_dim}")
        out_dim = getattr(differentiable_model, "output_dim", None)
        wanted = input_dim if baseline else 2
        if out_dim is not None and out_dim != wanted:
            raise ValueError(f"{'a baseline' if baseline else 'an HNN'}'s network must output {wanted} values "
                             f"({'dx/dt' if baseline else 'F1, F2'}), but it outputs {out_dim}")
        if not baseline and getattr(differentiable_model, "nonlinearity_name", None) in _PIECEWISE_LINEAR:
            warnings.warn(
                f"HNN with nonlinearity {differentiable_model.nonlinearity_name!r}: its second derivative "
                "vanishes almost everywhere, so the learned field is piecewise constant; use tanh "
                "(the paper's choice) or another smooth activation", stacklevel=2)
        self.input_dim = input_dim
        self.baseline = baseline
        self.field_type = field_type
        self.assume_canonical_coords = assume_canonical_coords
        self.differentiable_model = differentiable_model
        self.register_buffer("M", permutation_tensor(input_dim, assume_canonical_coords), persistent=False)

    def _check_input(self, x: torch.Tensor) -> None:
        if x.dim() != 2 or x.shape[1] != self.input_dim:
            raise ValueError(
                f"expected x of shape (batch, {self.input_dim}), got {tuple(x.shape)}; "
                "pass a batch of states, e.g. x.reshape(-1, input_dim)")

    def forward(self, x: torch.Tensor):
        """``(F1, F2)``, each ``(batch, 1)``; with ``baseline=True`` the network output ``(batch, input_dim)``."""
        self._check_input(x)
        y = self.differentiable_model(x)
        if self.baseline:
            return y
        if y.dim() != 2 or y.shape[1] != 2:
            raise ValueError(f"an HNN's network must output (batch, 2) = (F1, F2), got {tuple(y.shape)}")
        return y[:, :1], y[:, 1:]

    def hamiltonian(self, x: torch.Tensor) -> torch.Tensor:
        """The learned H = F2 at ``x``, shape ``(batch,)``."""
        if self.baseline:
            raise ValueError("a baseline model has no Hamiltonian; build it with baseline=False")
        return self.forward(x)[1].squeeze(1)

    def time_derivative(self, x: torch.Tensor, t=None, separate_fields: bool = False):
        """``dx/dt`` at ``x``, shape ``(batch, input_dim)``.

        The input gradient is autograd's (in closed form for the paper's tanh MLP, checked
        against autograd in the tests). Works with or without ``x.requires_grad`` and inside
        ``torch.no_grad()``: the graph for double backpropagation is built only when grad mode
        is on (training); in evaluation the result is detached. ``t`` is unused (autonomous
        systems). With ``separate_fields=True`` returns ``[conservative, solenoidal]``.
        """
        self._check_input(x)
        if self.baseline:
            return self.differentiable_model(x)
        create_graph = torch.is_grad_enabled()
        net = self.differentiable_model
        conservative = solenoidal = None
        if self.field_type != "solenoidal":
            conservative = _input_gradient(net, x, 0, create_graph)
        if self.field_type != "conservative":
            dF2 = _input_gradient(net, x, 1, create_graph)
            if self.assume_canonical_coords:
                n = self.input_dim // 2
                solenoidal = torch.cat([dF2[:, n:], -dF2[:, :n]], dim=1)
            else:
                solenoidal = dF2 @ self.M.to(dF2.dtype).T
        if separate_fields:
            zero = torch.zeros_like(x)
            return [zero if conservative is None else conservative, zero if solenoidal is None else solenoidal]
        if conservative is None:
            return solenoidal
        return conservative if solenoidal is None else conservative + solenoidal


def build_model(input_dim: int, hidden_dim: int = 200, nonlinearity: str = "tanh", baseline: bool = False,
                field_type: str = "solenoidal") -> HNN:
    """The paper's model for one task: ``HNN(input_dim, MLP(input_dim, hidden_dim, out))``.

    ``out`` is 2 (F1, F2) for the HNN and ``input_dim`` (dx/dt directly) for the baseline.
    """
    output_dim = input_dim if baseline else 2
    return HNN(input_dim, MLP(input_dim, hidden_dim, output_dim, nonlinearity),
               field_type=field_type, baseline=baseline)


class MLPAutoencoder(nn.Module):
    """The paper's pixel autoencoder: 4 layers each side, residual hidden layers, linear ends.

    Encoder ``(batch, input_dim) -> (batch, latent_dim)``: h = s(L1 x); h += s(L2 h); h += s(L3 h);
    z = L4 h. The decoder mirrors it back to ``input_dim`` (no output squashing). All 8 layers
    have biases and orthogonal weights.
    """

    def __init__(self, input_dim: int, hidden_dim: int, latent_dim: int, nonlinearity: str = "relu"):
        super().__init__()
        for label, value in (("input_dim", input_dim), ("hidden_dim", hidden_dim), ("latent_dim", latent_dim)):
            if not isinstance(value, int) or value < 1:
                raise ValueError(f"MLPAutoencoder {label} must be a positive integer, got {value!r}")
        self._act = get_nonlinearity(nonlinearity)
        self.input_dim, self.latent_dim = input_dim, latent_dim
        self.encoder = nn.ModuleList([nn.Linear(input_dim, hidden_dim), nn.Linear(hidden_dim, hidden_dim),
                                      nn.Linear(hidden_dim, hidden_dim), nn.Linear(hidden_dim, latent_dim)])
        self.decoder = nn.ModuleList([nn.Linear(latent_dim, hidden_dim), nn.Linear(hidden_dim, hidden_dim),
                                      nn.Linear(hidden_dim, hidden_dim), nn.Linear(hidden_dim, input_dim)])
        for layer in (*self.encoder, *self.decoder):
            nn.init.orthogonal_(layer.weight)

    def _run(self, layers: nn.ModuleList, x: torch.Tensor) -> torch.Tensor:
        h = self._act(layers[0](x))
        h = h + self._act(layers[1](h))
        h = h + self._act(layers[2](h))
        return layers[3](h)

    def encode(self, x: torch.Tensor) -> torch.Tensor:
        """Pixels ``(batch, input_dim)`` -> latents ``(batch, latent_dim)``."""
        if x.dim() != 2 or x.shape[1] != self.input_dim:
            raise ValueError(f"expected pixels of shape (batch, {self.input_dim}), got {tuple(x.shape)}")
        return self._run(self.encoder, x)

    def decode(self, z: torch.Tensor) -> torch.Tensor:
        """Latents ``(batch, latent_dim)`` -> pixels ``(batch, input_dim)``."""
        if z.dim() != 2 or z.shape[1] != self.latent_dim:
            raise ValueError(f"expected latents of shape (batch, {self.latent_dim}), got {tuple(z.shape)}")
        return self._run(self.decoder, z)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.decode(self.encode(x))


class PixelHNN(nn.Module):
    """An autoencoder whose latent z = [q, p] moves by an HNN (or, as the baseline, by a plain MLP).

    ``loss(x, x_next)`` is the paper's per-sample objective for a pair of pixel observations one
    frame apart, ``(batch, input_dim)`` each: reconstruction + canonical-coordinate term + 0.1 x
    the latent-dynamics term, where the latent moves by one step of size 1 (one frame) of
    ``time_derivative`` (Euler as the paper, or RK4).
    """

    def __init__(self, input_dim: int, latent_dim: int = 2, hidden_dim: int = 200, nonlinearity: str = "tanh",
                 baseline: bool = False, field_type: str = "solenoidal", autoencoder_nonlinearity: str = "relu"):
        super().__init__()
        if latent_dim % 2:
            raise ValueError(f"latent_dim must be even (z = [q, p]), got {latent_dim}")
        self.autoencoder = MLPAutoencoder(input_dim, hidden_dim, latent_dim, autoencoder_nonlinearity)
        self.hnn = build_model(latent_dim, hidden_dim, nonlinearity, baseline, field_type)
        self.input_dim, self.latent_dim, self.baseline = input_dim, latent_dim, baseline

    def encode(self, x: torch.Tensor) -> torch.Tensor:
        return self.autoencoder.encode(x)

    def decode(self, z: torch.Tensor) -> torch.Tensor:
        return self.autoencoder.decode(z)

    def time_derivative(self, z: torch.Tensor, t=None) -> torch.Tensor:
        """dz/dt per frame, ``(batch, latent_dim)``."""
        return self.hnn.time_derivative(z)

    def hamiltonian(self, z: torch.Tensor) -> torch.Tensor:
        """The learned H of latents ``(batch, latent_dim)``, ``(batch,)`` (HNN only)."""
        return self.hnn.hamiltonian(z)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """The pixels one frame later: decode(z + dz/dt) with z = encode(x)."""
        z = self.encode(x)
        return self.decode(z + self.time_derivative(z))

    def loss(self, x: torch.Tensor, x_next: torch.Tensor, input_noise: float = 0.0, use_rk4: bool = False,
             generator: torch.Generator | None = None) -> torch.Tensor:
        """The per-sample loss ``(batch,)``: ae + cc + 0.1 hnn.

        ae = mean over pixels of (x - decode(z))^2; hnn = mean over latents of
        (z' - (z + step(z + noise)))^2, one frame step; cc = mean over the n latent pairs of
        (p - (q' - q))^2, which makes p the per-frame change of q (z = [q, p], z' = encode(x_next)).
        """
        if x.shape != x_next.shape:
            raise ValueError(f"x and x_next must have the same shape, got {tuple(x.shape)} and {tuple(x_next.shape)}")
        z, z_next = self.encode(torch.cat([x, x_next])).split(len(x))
        # mse_loss has a fused backward: a third of pow(2)'s time over 200 x 1568 pixels (0.6 ms a step)
        ae = nn.functional.mse_loss(self.decode(z), x, reduction="none").mean(dim=1)
        zin = z if not input_noise else z + input_noise * torch.randn(z.shape, generator=generator).to(z)
        if use_rk4:
            step = rk4_step(self.time_derivative, zin, 1.0)
        else:
            step = self.time_derivative(zin)
        hnn = (z_next - (z + step)).pow(2).mean(dim=1)
        n = self.latent_dim // 2
        cc = (z[:, n:] - (z_next[:, :n] - z[:, :n])).pow(2).mean(dim=1)
        return ae + cc + 0.1 * hnn
