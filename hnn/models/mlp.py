"""The paper's MLP: two tanh hidden layers and a bias-free linear output, its activations, and
d(output)/dx (closed form for the tanh MLP, ``tanh_mlp``; autograd for any other network)."""
from __future__ import annotations

import torch
from torch import nn

from . import tanh_mlp
from ..names import INITS, NONLINEARITIES, checked
from ..interface import gradient_of
from ..modes import in_model_axis
from ..settings import RunSettings


def _swish(x: torch.Tensor) -> torch.Tensor:
    return x * torch.sigmoid(x)


_tanh = tanh_mlp.fast_tanh      # the closed-form kernels' own tanh (MLP._closed_form_applies looks for it)


# the activations get_nonlinearity knows (--nonlinearity's choices): hnn.names' list, each its function
_NONLINEARITIES = checked({"tanh": _tanh, "relu": torch.relu, "sigmoid": torch.sigmoid,
                           "softplus": nn.functional.softplus, "selu": torch.selu, "elu": nn.functional.elu,
                           "swish": _swish}, NONLINEARITIES, "hnn.models.mlp._NONLINEARITIES")

# Piecewise-linear activations: their second derivative is zero almost everywhere, so the
# symplectic gradient of an HNN built on them is piecewise constant in x and the training
# signal through d(dH/dx)/dtheta is poor.
PIECEWISE_LINEAR = {"relu"}


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

    def __init__(self, input_dim: int, hidden_dim: int, output_dim: int, nonlinearity: str = RunSettings.nonlinearity):
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
        # hnn.models.tanh_mlp.closed_form_input_gradient differentiates this function by hand: edit both together
        # (tests/test_models.py compares the two)
        h = self._act(self.linear1(x))
        h = self._act(self.linear2(h))
        return self.linear3(h)

    def input_gradient(self, x: torch.Tensor, k: int, create_graph: bool) -> torch.Tensor:
        """d(self(x)[:, k])/dx, ``(batch, input_dim)``: in closed form when ``_closed_form_applies``
        (faster training: docs/speed.md), else by autograd; with ``create_graph`` it can be differentiated."""
        if not self._closed_form_applies():
            return autograd_input_gradient(self, x, k, create_graph)
        l1, l2 = self.linear1, self.linear2
        params = (l1.weight, l1.bias, l2.weight, l2.bias, self.linear3.weight[k])
        return tanh_mlp.closed_form_input_gradient(x, *params)

    def _closed_form_applies(self) -> bool:
        """Whether ``self(x)`` is the network the closed form differentiates: ``MLP.forward`` as
        defined above (not overridden by a subclass, nor replaced on the class or the instance
        since), tanh, plain linear layers and no forward hooks, outside vmap over models (its hand-written
        backward has no batching rule: ``hnn.modes.model_axis``). Anything else gets autograd."""
        # read from the module's dicts directly: an integrator asks at every field call
        own, layers = self.__dict__, self._modules
        return (type(self).forward is _CLOSED_FORM_FORWARD and "forward" not in own
                and own["_act"] is tanh_mlp.fast_tanh and not (own["_forward_hooks"] or own["_forward_pre_hooks"])
                and type(layers["linear1"]) is nn.Linear and type(layers["linear2"]) is nn.Linear
                and type(layers["linear3"]) is nn.Linear and not in_model_axis())


def initialize(model: nn.Module, init: str) -> nn.Module:
    """Re-draw the weights of every ``MLP`` inside ``model`` by the scheme ``init`` (one of ``INITS``), in
    place; returns ``model``. Draws from torch's global generator, so a seeded run draws the same.

    - ``'orthogonal'``: as ``MLP`` builds them (orthogonal weights, torch's uniform biases): unchanged.
    - ``'zero_bias'``: orthogonal weights, every bias zero (DGNet's ``reset_parameters``, all its models).
    - ``'lnn'``: the LNN's init (``custom_init`` of Cranmer et al.'s ``lnn.py``): zero biases and weights
      N(0, s^2 / n) with n the larger side of the layer's matrix and s = 2.2 for the first layer, 0.58 i for
      hidden layer i, n for the output (so the output weights' std is sqrt(n)). An L's Euler-Lagrange
      equations do not see L's scale; the large output and small hidden weights set how Adam moves them.
    - ``'lnn_convex'``: the LNN's, with the weights after the first layer made nonnegative (their absolute
      values). With a convex nondecreasing activation (softplus) the network is then convex in its input at
      step 0, so an LNN's d2L/dqdot2 starts positive semidefinite at every state: its first accelerations are
      the data's size (at most 14 on CHNN's chains) where the LNN's reach 10^5 and its first RK4 snippet
      fails (docs/stress.md, "The LNN's start"). Training moves the weights anywhere after.
    """
    if init not in INITS:
        raise ValueError(f"unknown init {init!r}; choose one of {', '.join(INITS)}")
    if init == "orthogonal":
        return model
    for mlp in (m for m in model.modules() if isinstance(m, MLP)):
        layers = (mlp.linear1, mlp.linear2, mlp.linear3)
        with torch.no_grad():
            for i, layer in enumerate(layers):
                if layer.bias is not None:
                    layer.bias.zero_()
                if init in ("lnn", "lnn_convex"):
                    n = max(layer.weight.shape)
                    scale = 2.2 if i == 0 else n if i == len(layers) - 1 else 0.58 * i
                    layer.weight.normal_(0.0, scale / n ** 0.5)
                    if init == "lnn_convex" and i > 0:
                        layer.weight.abs_()
    return model


# the forward the closed form was written for, taken at import: a forward patched in later differs
_CLOSED_FORM_FORWARD = MLP.forward

def input_gradient(model: nn.Module, x: torch.Tensor, k: int, create_graph: bool) -> torch.Tensor:
    """d(model(x)[:, k])/dx, ``(batch, input_dim)``: an ``MLP`` computes its own (closed form when
    it applies), any other network goes through autograd."""
    if isinstance(model, MLP):
        return model.input_gradient(x, k, create_graph)
    return autograd_input_gradient(model, x, k, create_graph)


def autograd_input_gradient(model: nn.Module, x: torch.Tensor, k: int, create_graph: bool) -> torch.Tensor:
    """d(model(x)[:, k])/dx by autograd, ``(batch, input_dim)``; ``model`` must output ``(batch, 2)``."""
    def output_k(x_in):
        out = model(x_in)
        if out.dim() != 2 or out.shape[1] != 2:
            raise ValueError(f"an HNN's network must output (batch, 2) = (F1, F2), got {tuple(out.shape)}")
        return out[:, k]
    return gradient_of(output_k, x, create_graph)
