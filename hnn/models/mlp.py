"""The paper's MLP: two tanh hidden layers and a bias-free linear output, its activations, and
d(output)/dx (closed form for the tanh MLP, ``tanh_mlp``; autograd for any other network)."""
from __future__ import annotations

import torch
from torch import nn

from . import tanh_mlp
from ..interface import gradient_of

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
        since), tanh, plain linear layers and no forward hooks. Anything else gets autograd."""
        # read from the module's dicts directly: an integrator asks at every field call
        own, layers = self.__dict__, self._modules
        return (type(self).forward is _CLOSED_FORM_FORWARD and "forward" not in own
                and own["_act"] is tanh_mlp.fast_tanh and not (own["_forward_hooks"] or own["_forward_pre_hooks"])
                and type(layers["linear1"]) is nn.Linear and type(layers["linear2"]) is nn.Linear
                and type(layers["linear3"]) is nn.Linear)


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
