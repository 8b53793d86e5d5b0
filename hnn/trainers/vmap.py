"""Models of any kind trained as one program: their parameters stacked along a leading model axis and
every step one ``torch.func.vmap`` over the models (torch's recipe: ``stack_module_state``,
``functional_call``, ``vmap``).

    stats, failures = hnn.trainers.vmap.train_vmap(models, data, tests, seeds=[0, 1, 2], loss_of=loss_of, ...)

``hnn.trainers.closed_form.train_closed_form`` is the faster path for the paper's tanh-MLP kinds (a hand-written batched
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

from typing import Callable

import torch
from torch import nn
from torch.func import functional_call, stack_module_state, vmap

from ..integrators.groups import shared_buffers
from ..modes import model_axis
from ..settings import RunSettings
from .group_loop import WeightStack, group_loop, group_settings, group_stats
from .loop import adam_optimizer
from .rows import GroupRows, check_data


class _Loss(nn.Module):
    """``loss(x, y)`` as a module holding ``model``, so that ``functional_call`` swaps the model's weights."""

    def __init__(self, model: nn.Module, loss: Callable):
        super().__init__()
        self.model, self.loss = model, loss

    def forward(self, x: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
        return self.loss(x, y)


def train_vmap(models: list[nn.Module], data: list[tuple], tests: list[tuple] | None = None, *,
                loss_of: Callable[[nn.Module], Callable], seeds: list[int],
                total_steps: int = RunSettings.total_steps, learn_rate: float = RunSettings.learn_rate,
                weight_decay: float = RunSettings.weight_decay, batch_size: int | None = RunSettings.batch_size,
                print_every: int = RunSettings.print_every, test_every: int | None = None, input_noise: float = 0.0,
                optimizer: str = RunSettings.optimizer, schedule: str = RunSettings.schedule,
                clip_grad: float = RunSettings.clip_grad,
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
        checkpoint, checkpoint_every: as ``hnn.trainers.closed_form.train_closed_form``'s.

    Returns:
        ``(stats, failures)`` as ``hnn.trainers.closed_form.train_closed_form``'s.
    """
    if not models:
        raise ValueError("train_vmap needs at least one model")
    if len(data) != len(models) or len(seeds) != len(models) or (tests is not None and len(tests) != len(models)):
        raise ValueError(f"{len(models)} models need as many data pairs, seeds and test pairs; got {len(data)}, "
                         f"{len(seeds)} and {None if tests is None else len(tests)}")
    # buffers hold a model's structure (index maps, Hamilton's matrix), the same in every model: shared,
    # not stacked (an index buffer batched under vmap would index per model)
    buffers = shared_buffers(models)
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
        failures, curves, seconds = group_loop(
            weights, optim, train_rows, test_rows, losses, names=names, total_steps=total_steps,
            test_every=test_every, input_noise=input_noise, label="vmap group", progress=progress,
            checkpoint=checkpoint, checkpoint_every=checkpoint_every, learn_rate=learn_rate, schedule=schedule,
            clip_grad=clip_grad, check_gradients=True)

    def write_back(g: int, model: nn.Module) -> None:
        for name, param in model.named_parameters():
            param.copy_(params[name][g])
    return group_stats(models, failures, write_back, *curves, seconds)



def train_prepared(preps: list, checkpoint=None, names: list[str] | None = None,
                   progress: bool = False) -> tuple[list[dict | None], dict]:
    """Train the prepared runs ``preps`` (``hnn.policy.prepare``, of one vmap group: equal
    ``hnn.sweeps.group_runs.vmap_key``) as one program: each ``canonical_model`` on its own rows, the loss and
    options of the first one's objective (``Prepared.options``, as ``hnn.train`` reads them), built once
    for the group, so every dataset must give it the same time step and coordinates; ``train_vmap``'s
    ``(stats, failures)``."""
    for key in ("dt", "state"):
        if len({str(p.dataset.get(key)) for p in preps}) > 1:
            raise ValueError(f"a group's datasets differ in {key!r}: train these runs alone")
    training, options = preps[0].specs.training, preps[0].options
    return train_vmap([p.canonical_model for p in preps], [(p.x, p.y) for p in preps], [(p.test_x, p.test_y) for p in preps],
                      loss_of=options.loss_of, optimizer=training.optimizer, schedule=training.schedule,
                      clip_grad=training.clip_grad, input_noise=options.input_noise, names=names, progress=progress,
                      checkpoint=checkpoint, **group_settings(preps))


__all__ = ["train_prepared", "train_vmap"]
