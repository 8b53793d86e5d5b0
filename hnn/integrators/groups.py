"""A group's models rolled out together: every model of a group from its own starts (``rollout_group``),
and a group's field as one function of all its rows (``group_field``) for a row-wise method, each model's
weights stacked along a model axis under ``torch.func.vmap``. Beside ``rollout``: fields in, paths out;
the models are any ``nn.Module`` with a ``time_derivative``, read through ``functional_call`` alone."""
from __future__ import annotations

from typing import Callable

import torch
from torch import nn
from torch.func import functional_call, stack_module_state, vmap

from ..modes import model_axis
from .integrate import rollout
from .solvers import get_solver


class _Rollout(nn.Module):
    def __init__(self, model: nn.Module, t_eval, method: str, options: dict):
        super().__init__()
        self.model, self.t_eval, self.method, self.options = model, t_eval, method, options

    def forward(self, x0: torch.Tensor) -> torch.Tensor:
        return rollout(self.model, x0, self.t_eval, method=self.method, threads=None, **self.options)


class _Field(nn.Module):
    """``model.time_derivative`` as a module's forward, so that ``functional_call`` swaps the model's weights."""

    def __init__(self, model: nn.Module):
        super().__init__()
        self.model = model

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.model.time_derivative(x)


def shared_buffers(models: list[nn.Module]) -> dict:
    """The buffers a group's models share; ValueError for models of other classes, shapes or buffers."""
    if not models:
        raise ValueError("a group needs at least one model")
    shapes = [{k: v.shape for k, v in m.state_dict().items()} for m in models]
    if any(type(m) is not type(models[0]) or s != shapes[0] for m, s in zip(models, shapes)):
        raise ValueError("a group's models must be of one class with parameters of the same shapes")
    buffers = dict(models[0].named_buffers())
    if any(not torch.equal(b, buffers[k]) for m in models[1:] for k, b in m.named_buffers()):
        raise ValueError("a group's models must share their buffers (structure, not weights)")
    return buffers


def group_field(models: list[nn.Module]) -> Callable[[torch.Tensor], torch.Tensor]:
    """The field of a group as one function of ``(G * batch, dim)`` rows: block g of ``batch`` rows is
    stepped by ``models[g]``, all G in one vmap over the stacked weights (a snapshot: later changes to
    the models' weights are not seen). For a rollout whose method is ``row_wise``
    (``hnn.integrators.solvers.Solver``), so that every row reaches every call in its place."""
    buffers = shared_buffers(models)
    params = {k: v.detach() for k, v in stack_module_state(models)[0].items()}
    wrapper = _Field(models[0])
    state_buffers = {f"model.{k}": v for k, v in buffers.items()}

    def one(p: dict, x: torch.Tensor) -> torch.Tensor:
        return functional_call(wrapper, {**{f"model.{k}": v for k, v in p.items()}, **state_buffers}, (x,))

    def field(x: torch.Tensor) -> torch.Tensor:
        if len(x) % len(models):
            raise ValueError(f"a group of {len(models)} models steps G * batch rows, got {len(x)} rows: pass every "
                             "row to every call (a row_wise method; dopri5 and dop853 with drop_finished=False)")
        with model_axis():
            return vmap(one)(params, x.reshape(len(models), -1, x.shape[-1])).reshape(x.shape)
    return field


def group_options(method: str) -> dict:
    """The options a ``row_wise`` method needs to step a ``group_field``: every row to every call."""
    return {"drop_finished": False} if "drop_finished" in get_solver(method).accepts() else {}


def rollout_group(models: list[nn.Module], x0: torch.Tensor, t_eval, method: str = "rk4",
                    **options) -> torch.Tensor:
    """Every model of a group rolled out from its own starts: ``x0`` ``(G, batch, dim)`` (or ``(batch, dim)``,
    the same starts for all) -> ``(G, batch, len(t_eval), dim)``, as ``hnn.rollout`` of each model.

    A method whose ``Solver`` declares ``vmap`` integrates the whole group in one program (vmap over the stacked
    weights; ``hnn.rollout``'s checks of blown-up rows are skipped there, so a row that blows up shows
    as non-finite values). The per-row adaptive methods (dopri5, dop853) integrate the group's rows in
    one call of ``hnn.rollout`` on its ``group_field``, each row with its own steps, so each model's path
    is its own. Any other method rolls the models out one after another (solve_ivp's step is shared
    by the batch, the implicit methods' iterations too). No autograd graph."""
    x0 = torch.as_tensor(x0)
    x0 = x0.expand(len(models), *x0.shape) if x0.dim() == 2 else x0
    if x0.dim() != 3 or len(x0) != len(models):
        raise ValueError(f"x0 must be (G, batch, dim) with G = {len(models)} models, or (batch, dim); got "
                         f"{tuple(x0.shape)}")
    if not get_solver(method).vmap:
        # steps='shared' ties every row to one step size: each model then needs its own integration
        if not get_solver(method).row_wise or options.get("steps") == "shared":
            return torch.stack([rollout(m, x, t_eval, method=method, threads=None, **options) for m, x in zip(models, x0)])
        paths = rollout(group_field(models), x0.reshape(-1, x0.shape[-1]), t_eval, method=method, threads=None,
                        **options, **group_options(method))
        return paths.reshape(*x0.shape[:2], *paths.shape[1:])
    buffers = shared_buffers(models)
    params, _ = stack_module_state(models)
    wrapper = _Rollout(models[0], t_eval, method, options)

    def one(p: dict, x: torch.Tensor) -> torch.Tensor:
        state = {**{f"model.{k}": v.detach() for k, v in p.items()}, **{f"model.{k}": v for k, v in buffers.items()}}
        return functional_call(wrapper, state, (x,))

    with torch.no_grad(), model_axis():
        return vmap(one)(params, x0)


__all__ = ["group_field", "group_options", "rollout_group", "shared_buffers"]
