"""The paper's networks: the MLP and the Hamiltonian Neural Network built on it.

State convention: ``x = [q, p]`` of shape ``(batch, 2n)``; the first half is the
position half, the second half the momentum half.
"""
from __future__ import annotations

import warnings

import torch
from torch import nn

from . import tanh_mlp
from .interface import ANY_STATE, UNIT_MASS, Model

_NONLINEARITIES = {
    "tanh": tanh_mlp.fast_tanh,
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
FIELD_ROWS = {"solenoidal": (1,), "conservative": (0,), "both": (0, 1)}   # the outputs (F1, F2) each field reads


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
        # hnn.tanh_mlp._tanh_mlp_input_gradient differentiates this function by hand: edit both together
        # (tests/test_models.py compares the two)
        h = self._act(self.linear1(x))
        h = self._act(self.linear2(h))
        return self.linear3(h)

    def input_gradient(self, x: torch.Tensor, k: int, create_graph: bool) -> torch.Tensor:
        """d(self(x)[:, k])/dx, ``(batch, input_dim)``: in closed form when ``_closed_form_applies``
        (faster training: docs/speed.md), else by autograd; with ``create_graph`` it can be differentiated."""
        if not self._closed_form_applies():
            return _autograd_input_gradient(self, x, k, create_graph)
        l1, l2 = self.linear1, self.linear2
        params = (l1.weight, l1.bias, l2.weight, l2.bias, self.linear3.weight[k])
        if not torch.is_grad_enabled():     # evaluation: skip the autograd node
            return tanh_mlp._evaluation_input_gradient(x, *params)
        return tanh_mlp._TanhMLPInputGradient.apply(x, *params)

    def _closed_form_applies(self) -> bool:
        """Whether ``self(x)`` is the network the closed form differentiates: ``MLP.forward`` as
        defined above (not overridden by a subclass, nor replaced on the class or the instance
        since), tanh, plain linear layers and no forward hooks. Anything else gets autograd."""
        # read from the module's dicts directly: an integrator asks at every field call
        own, layers = self.__dict__, self._modules
        return (type(self).forward is _CLOSED_FORM_FORWARD and "forward" not in own
                and own["_act"] is tanh_mlp.fast_tanh and not (own["_forward_hooks"] or own["_forward_pre_hooks"])
                and type(layers["linear1"]) is nn.Linear and type(layers["linear2"]) is nn.Linear
                and type(layers["linear3"]) is nn.Linear)


# the forward the closed form was written for, taken at import: a forward patched in later differs
_CLOSED_FORM_FORWARD = MLP.forward


def permutation_tensor(n: int) -> torch.Tensor:
    """The ``(n, n)`` matrix M = [[0, I], [-I, 0]] of Hamilton's equations, ``dx/dt = grad H @ M.T``."""
    eye = torch.eye(n)
    return torch.cat([eye[n // 2:], -eye[: n // 2]])


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


class HNN(Model):
    """Hamiltonian Neural Network (Greydanus et al. 2019).

    ``differentiable_model`` maps ``(batch, input_dim)`` to two scalar fields ``(F1, F2)``
    (shape ``(batch, 2)``), or, with ``baseline=True``, directly to ``dx/dt`` of shape
    ``(batch, input_dim)`` (then the instance declares ``conservative=False``, as ``hnn.Baseline``).
    ``time_derivative`` builds the vector field from the autograd gradient: the solenoidal part
    ``grad F2 @ M.T`` (Hamilton's equations with H = F2), the conservative part ``grad F1``, or both.
    """
    conservative = True
    takes = UNIT_MASS

    def __init__(self, input_dim: int, differentiable_model: nn.Module, field_type: str = "solenoidal",
                 baseline: bool = False):
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
        if baseline:
            self.conservative, self.takes = False, ANY_STATE
        self.field_type = field_type
        self.differentiable_model = differentiable_model
        self.register_buffer("M", permutation_tensor(input_dim), persistent=False)

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

    def exact_discrete_gradient(self):
        """DGNet's discrete gradient of the paper's tanh MLP (``hnn.tanh_mlp.discrete_gradient``), else None."""
        net = self.differentiable_model
        if self.baseline or self.field_type != "solenoidal" or not (isinstance(net, MLP) and net._closed_form_applies()):
            return None
        return lambda x0, x1: tanh_mlp.discrete_gradient(x0, x1, *tanh_mlp.mlp_weights(net)[:4], net.linear3.weight[1])

    def time_derivative(self, x: torch.Tensor, t=None):
        """``dx/dt`` at ``x``, shape ``(batch, input_dim)``.

        The input gradient is autograd's (in closed form for the paper's tanh MLP, checked
        against autograd in the tests). Works with or without ``x.requires_grad`` and inside
        ``torch.no_grad()``: the graph for double backpropagation is built only when grad mode
        is on (training); in evaluation the result is detached. ``t`` is unused (autonomous
        systems).
        """
        if not torch.is_grad_enabled():
            kernel = self._evaluation_kernel()
            if kernel is not None and kernel.serves(x):
                return kernel(x)
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
            n = self.input_dim // 2
            solenoidal = torch.cat([dF2[:, n:], -dF2[:, :n]], dim=1)
        if conservative is None:
            return solenoidal
        return conservative if solenoidal is None else conservative + solenoidal


    def _evaluation_kernel(self):
        """The field as one ``hnn.tanh_mlp.EvaluationKernel`` (the evaluation path for a few states), or
        None when the network is not the paper's tanh MLP."""
        net = self._modules["differentiable_model"]
        if not isinstance(net, MLP):
            return None
        if self.baseline:
            return tanh_mlp.cached_kernel(self, "field", net, None)
        rows = FIELD_ROWS[self.field_type]
        return tanh_mlp.cached_kernel(self, "field", net, rows, lambda: self._fold(rows))

    def _fold(self, rows: tuple[int, ...]) -> torch.Tensor:
        """How d(F_k)/dx enters dx/dt for each k of ``rows``: F1's gradient as it is, F2's through M^T."""
        eye, hamilton = torch.eye(self.input_dim), self.M.detach().cpu().T
        return torch.stack([{0: eye, 1: hamilton}[k] for k in rows])


class Baseline(HNN):
    """The paper's baseline: an MLP ``(batch, input_dim) -> dx/dt``, no H, any state it is given."""
    conservative = False
    takes = ANY_STATE

    def __init__(self, input_dim: int, differentiable_model: nn.Module, field_type: str = "solenoidal"):
        super().__init__(input_dim, differentiable_model, field_type, baseline=True)


def build_model(input_dim: int, hidden_dim: int = 200, nonlinearity: str = "tanh", baseline: bool = False,
                field_type: str = "solenoidal") -> HNN:
    """The paper's model for one task: ``HNN(input_dim, MLP(input_dim, hidden_dim, out))``, or ``Baseline``.

    ``out`` is 2 (F1, F2) for the HNN and ``input_dim`` (dx/dt directly) for the baseline.
    """
    if baseline:
        return Baseline(input_dim, MLP(input_dim, hidden_dim, input_dim, nonlinearity), field_type)
    return HNN(input_dim, MLP(input_dim, hidden_dim, 2, nonlinearity), field_type=field_type)


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


class PixelHNN(Model):
    """An autoencoder whose latent z = [q, p] moves by an HNN (or, as the baseline, by a plain MLP).

    It is trained by ``hnn.objectives.pixel_loss(model, x, x_next)``, the paper's per-sample
    objective for a pair of pixel observations one frame apart: reconstruction + canonical-coordinate
    term + 0.1 x the latent-dynamics term, where the latent moves by one step of size 1 (one frame)
    of ``time_derivative``. Its ``time_derivative`` reads latents.
    """
    coordinates = "latent"
    conservative = True

    def __init__(self, input_dim: int, latent_dim: int = 2, hidden_dim: int = 200, nonlinearity: str = "tanh",
                 baseline: bool = False, field_type: str = "solenoidal", autoencoder_nonlinearity: str = "relu"):
        super().__init__()
        if latent_dim % 2:
            raise ValueError(f"latent_dim must be even (z = [q, p]), got {latent_dim}")
        self.autoencoder = MLPAutoencoder(input_dim, hidden_dim, latent_dim, autoencoder_nonlinearity)
        self.hnn = build_model(latent_dim, hidden_dim, nonlinearity, baseline, field_type)
        self.input_dim, self.latent_dim, self.baseline = input_dim, latent_dim, baseline
        if baseline:
            self.conservative = False

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


class PixelBaseline(PixelHNN):
    """``PixelHNN`` whose latent moves by a plain MLP (the paper's pixel baseline): no H."""
    conservative = False

    def __init__(self, input_dim: int, latent_dim: int = 2, hidden_dim: int = 200, nonlinearity: str = "tanh",
                 field_type: str = "solenoidal", autoencoder_nonlinearity: str = "relu"):
        super().__init__(input_dim, latent_dim, hidden_dim, nonlinearity, True, field_type, autoencoder_nonlinearity)
