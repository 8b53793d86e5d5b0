"""Models of any kind trained as one program: their parameters stacked along a leading model axis and
every step one ``torch.func.vmap`` over the models (torch's recipe: ``stack_module_state``,
``functional_call``, ``vmap``).

    stats, failures = hnn.stacked.fit_stacked(models, data, tests, seeds=[0, 1, 2], loss_of=loss_of, ...)

``hnn.grouped.fit_group`` is the faster path for the paper's tanh-MLP kinds (a hand-written batched
closed form); this one serves every other kind and objective the studies train: the mechanical,
second-order, constrained and Lagrangian kinds, other activations, trajectory snippets, the discrete
gradient. It runs inside ``hnn.modes.model_axis``, where input gradients take ``torch.func.grad``
(``torch.autograd.grad`` does not run under vmap) and checks that read a value are skipped: a
model whose loss turns NaN or infinite is named and dropped, the others go on.

Each model keeps what its lone run has: its init, its rows and minibatch stream (``GroupRows``), its
input noise, its own Adam or AdamW state (elementwise, so one optimizer over the stacked tensors is G
independent ones), its own gradient clipping (each model's norm), the shared rate schedule. Its numbers
equal its lone run's up to float rounding (tests/test_stacked.py says how close).
"""
from __future__ import annotations

import json
from typing import Callable

import torch
from torch import nn
from torch.func import functional_call, stack_module_state, vmap

from .grouped import GroupRows, WeightStack, group_key, group_stats, train_steps
from .integrators.integrate import rollout
from .integrators.solvers import get_solver
from .kinds import get_kind
from .modes import model_axis
from .training import adam_optimizer, check_data


# the fields that may differ within a stacked group: each model's seed, data fraction and init
_OWN_FIELDS = ("seed", "train_fraction", "init")


def stack_key(config) -> tuple | None:
    """Configs with equal keys can train as one stacked group (``fit_stacked``); None for a config that
    ``hnn.grouped.group_key`` groups (its closed form is faster) or that trains alone: the pixel kinds
    (their objective draws noise of its own). The key is the run's identity less ``_OWN_FIELDS``, and
    the facts its model is built from (the chain's constraints)."""
    if group_key(config) is not None or get_kind(config.kind).grouping == "alone":
        return None
    same = {k: v for k, v in config.identity().items() if k not in _OWN_FIELDS}
    return (type(config).__module__, type(config).__qualname__,      # the identity's JSON: a hashable key
            json.dumps({**same, **config.model_facts()}, sort_keys=True, default=str))


class _Loss(nn.Module):
    """``loss(x, y)`` as a module holding ``model``, so that ``functional_call`` swaps the model's weights."""

    def __init__(self, model: nn.Module, loss: Callable):
        super().__init__()
        self.model, self.loss = model, loss

    def forward(self, x: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
        return self.loss(x, y)


def fit_stacked(models: list[nn.Module], data: list[tuple], tests: list[tuple] | None = None, *,
                loss_of: Callable[[nn.Module], Callable], seeds: list[int], total_steps: int = 2000,
                learn_rate: float = 1e-3, weight_decay: float = 1e-4, batch_size: int | None = None,
                print_every: int = 200, test_every: int | None = None, input_noise: float = 0.0,
                optimizer: str = "adam", schedule: str = "constant", clip_grad: float = 0.0,
                names: list[str] | None = None, progress: bool = False, checkpoint=None,
                checkpoint_every: float | None = None) -> tuple[list[dict | None], dict]:
    """Train ``models`` (one class and shape, the same structure) together, as ``hnn.train`` trains each
    alone; their weights are updated in place.

    Args:
        data, tests: each model's ``(inputs, targets)`` and ``(test inputs, test targets)``, ``(rows, width)``.
        loss_of: ``loss_of(model) -> (x, y) -> loss per row or element`` (``(rows,)`` or ``(rows, k)``), the
            loss ``hnn.train`` would minimize for ``model``; called once, on a copy whose weights each
            model's slice replaces.
        seeds: each model's ``hnn.train`` seed (its minibatches and input noise).
        input_noise, optimizer, schedule, clip_grad: as ``hnn.train``'s.
        checkpoint, checkpoint_every: as ``hnn.grouped.fit_group``'s.

    Returns:
        ``(stats, failures)`` as ``hnn.grouped.fit_group``'s.
    """
    if not models:
        raise ValueError("fit_stacked needs at least one model")
    if len(data) != len(models) or len(seeds) != len(models) or (tests is not None and len(tests) != len(models)):
        raise ValueError(f"{len(models)} models need as many data pairs, seeds and test pairs; got {len(data)}, "
                         f"{len(seeds)} and {None if tests is None else len(tests)}")
    # buffers hold a model's structure (index maps, Hamilton's matrix), the same in every model: shared,
    # not stacked (an index buffer batched under vmap would index per model)
    buffers = _check_group(models)
    params, _ = stack_module_state(models)
    names = names or [f"model {g}" for g in range(len(models))]
    first = next(iter(params.values()))
    kw = dict(dtype=first.dtype, device=first.device)
    train_rows = GroupRows([check_data("x", x, **kw) for x, _ in data], [check_data("y", y, **kw) for _, y in data],
                           batch_size, seeds, 0)
    test_rows = None if tests is None else GroupRows([check_data("test_x", x, **kw) for x, _ in tests],
                                                      [check_data("test_y", y, **kw) for _, y in tests],
                                                      batch_size, seeds, 1)
    wrapper = _Loss(models[0], loss_of(models[0]))
    keys = list(params)

    def one(p: dict, b: dict, x: torch.Tensor, y: torch.Tensor, w: torch.Tensor) -> torch.Tensor:
        state = {**{f"model.{k}": v for k, v in p.items()}, **{f"model.{k}": v for k, v in b.items()}}
        per = functional_call(wrapper, state, (x, y))
        return (per.reshape(len(x), -1).mean(1) * w).sum()       # the mean over the model's drawn rows

    def losses(rows: GroupRows, x: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
        row_weight = rows.weight * rows.x.shape[2]         # 1 / drawn rows, 0 on padding
        return vmap(one, in_dims=(0, None, 0, 0, 0))(params, buffers, x, y, row_weight)

    test_every = print_every if test_every is None else test_every
    weights = [params[k] for k in keys]
    optim = adam_optimizer(WeightStack(weights), learn_rate, weight_decay, optimizer)
    # a model's loss may stay finite while its gradient is not (a second derivative through a solve):
    # its gradient is checked too
    with model_axis():
        failures, curves, seconds = train_steps(
            weights, optim, train_rows, test_rows, losses, names=names, total_steps=total_steps,
            test_every=test_every, input_noise=input_noise, label="stacked", progress=progress,
            checkpoint=checkpoint, checkpoint_every=checkpoint_every, learn_rate=learn_rate, schedule=schedule,
            clip_grad=clip_grad, check_gradients=True)

    def write_back(g: int, model: nn.Module) -> None:
        for name, param in model.named_parameters():
            param.copy_(params[name][g])
    return group_stats(models, failures, write_back, *curves, seconds)


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


def _check_group(models: list[nn.Module]) -> dict:
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
    buffers = _check_group(models)
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


def rollout_stacked(models: list[nn.Module], x0: torch.Tensor, t_eval, method: str = "rk4",
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
        if not get_solver(method).row_wise:
            return torch.stack([rollout(m, x, t_eval, method=method, threads=None, **options) for m, x in zip(models, x0)])
        paths = rollout(group_field(models), x0.reshape(-1, x0.shape[-1]), t_eval, method=method, threads=None,
                        **options, **group_options(method))
        return paths.reshape(*x0.shape[:2], *paths.shape[1:])
    buffers = _check_group(models)
    params, _ = stack_module_state(models)
    wrapper = _Rollout(models[0], t_eval, method, options)

    def one(p: dict, x: torch.Tensor) -> torch.Tensor:
        state = {**{f"model.{k}": v.detach() for k, v in p.items()}, **{f"model.{k}": v for k, v in buffers.items()}}
        return functional_call(wrapper, state, (x,))

    with torch.no_grad(), model_axis():
        return vmap(one)(params, x0)


__all__ = ["fit_stacked", "group_field", "group_options", "rollout_stacked", "stack_key"]
