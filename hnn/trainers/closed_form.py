"""The closed-form group: many small models of one kind trained as one program, their parameters stacked
along a leading model axis and every product of a step one hand-written batched product over the models
(the input gradient of the paper's tanh MLP in closed form; ``hnn.trainers.vmap`` serves every other kind).

    stats, failures = hnn.trainers.closed_form.train_closed_form(models, data, tests, seeds=[0, 1, 2, 3], ...)
    folders = hnn.sweeps.group_runs.train_group([SpringConfig(seed=s, hidden_dim=32) for s in range(4)])   # saved runs

A small HNN's step is mostly dispatch, not arithmetic; G of them as one batched step share one
dispatch (``python analysis/benchmarks/benchmark.py --jobs group`` measures the model-steps per second
against separate runs). Each model keeps what its lone run has: its
init (built as ``hnn.run_experiment`` builds it, from its seed), its data subset
(``train_fraction``), its minibatch stream (its own generator, drawing the lone run's indices),
its own Adam state (Adam is elementwise, so one optimizer over the stacked tensors is G
independent ones) and its own dataset (a group may mix seeds). The loss summed over the models
has, for each model's parameters, that model's own gradient: the batched products keep the
models apart. A run trained in a group gives its lone run's numbers up to float rounding
(tests/test_grouped.py measures how close), and is saved as its own ordinary run folder.

A model whose loss turns NaN or infinite is reported by name, its slice zeroed and left out of
the remaining updates; the others go on unaffected.

Groupable: the ``hnn``, ``baseline``, ``dissipative`` and ``separable`` kinds on the paper's tanh
MLP, fitting dx/dt itself (``DerivativeObjective`` without ``use_rk4``); ``hnn.sweeps.group_runs.closed_form_key``
says which configs train together. Widths group apart, not padded to the widest: a padded unit is not
exactly inert under weight decay and Adam, and from width 64 on a step is near its arithmetic
floor, so padding 16 to 64 would cost the wide step's products (benchmark ``group`` job).
"""
from __future__ import annotations

import torch

from ..models.hamiltonian import FIELD_ROWS, HNN
from ..models.mlp import MLP
from ..models.structured import SeparableHNN
from ..models.tanh_mlp import closed_form_input_gradient, fast_tanh
from ..settings import RunSettings
from .group_loop import GroupedRunFailed, WeightStack, group_loop, group_settings, group_stats
from .loop import adam_optimizer
from .rows import GroupRows, check_data


def _nets(model) -> list[MLP]:
    """The tanh MLPs of a model, in the order their slices stack: net j of model g at ``j * G + g``."""
    nets = [model.kinetic_net, model.potential_net] if isinstance(model, SeparableHNN) else [model.differentiable_model]
    for net in nets:
        if not (isinstance(net, MLP) and net._closed_form_applies()):
            raise ValueError("a group trains models on the paper's tanh MLP only; train this model alone")
    return nets


def _layers(net: MLP) -> tuple:
    return net.linear1.weight, net.linear1.bias, net.linear2.weight, net.linear2.bias, net.linear3.weight


def _stacked_weights(models: list) -> list[torch.Tensor]:
    """``[W1, b1, W2, b2, W3]``, the models' nets stacked along a new leading axis (``_nets``), as leaves."""
    nets = [list(column) for column in zip(*(_nets(model) for model in models))]
    layers = [_layers(net) for column in nets for net in column]
    return [torch.stack([ws[i].detach() for ws in layers]).clone().requires_grad_(True) for i in range(5)]


def _field(weights, x: torch.Tensor, baseline: bool, rows: tuple[int, ...] | None) -> torch.Tensor:
    """dx/dt of every model at its own states ``x`` ``(G, batch, n)``: ``(G, batch, n)``; ``rows``
    None for separable models (kinetic nets, then potential nets: ``(dT/dp, -dV/dq)``)."""
    W1, b1, W2, b2, W3 = weights
    if rows is None:
        half = x.shape[-1] // 2
        q, p = x[..., :half], x[..., half:]
        grad = closed_form_input_gradient(torch.cat([p, q]), W1, b1, W2, b2, W3[:, 0])
        kinetic, potential = grad.split(len(x))
        return torch.cat([kinetic, -potential], dim=-1)
    if baseline:
        h1 = fast_tanh(torch.baddbmm(b1.unsqueeze(1), x, W1.transpose(1, 2)))
        h2 = fast_tanh(torch.baddbmm(b2.unsqueeze(1), h1, W2.transpose(1, 2)))
        return torch.bmm(h2, W3.transpose(1, 2))
    n = x.shape[-1] // 2
    out = None
    for k in rows:                                   # 0: F1 (conservative), 1: F2 (Hamilton's equations)
        grad = closed_form_input_gradient(x, W1, b1, W2, b2, W3[:, k])
        part = grad if k == 0 else torch.cat([grad[..., n:], -grad[..., :n]], dim=-1)
        out = part if out is None else out + part
    return out


def train_closed_form(models: list[HNN], data: list[tuple], tests: list[tuple] | None = None, *, seeds: list[int],
              total_steps: int = RunSettings.total_steps, learn_rate: float = RunSettings.learn_rate,
              weight_decay: float = RunSettings.weight_decay, batch_size: int | None = RunSettings.batch_size,
              print_every: int = RunSettings.print_every, test_every: int | None = None,
              input_noise: float = 0.0, names: list[str] | None = None, after_step=None,
              progress: bool = False, checkpoint=None,
              checkpoint_every: float | None = None) -> tuple[list[dict | None], dict[int, GroupedRunFailed]]:
    """Train ``models`` (of one kind and width on the tanh MLP: HNNs, baselines, dissipative or
    separable HNNs) together, as ``hnn.train`` trains each alone; their weights are updated in place.

    Args:
        data: each model's ``(x, dxdt)``, ``(rows, n)`` arrays or tensors (rows may differ).
        tests: each model's ``(test_x, test_dxdt)``, or None.
        seeds: each model's ``hnn.train`` seed (its minibatches and input noise).
        names: each model's name in a failure's report (default ``model <index>``).
        after_step: ``after_step(step, weights)`` after each optimizer step, with the stacked
            ``[W1, b1, W2, b2, W3]`` (a test poisons one model's slice with it).
        checkpoint, checkpoint_every: the group's training checkpoint (``GroupCheckpoint``): saved there
            every ``checkpoint_every`` seconds, resumed from where the file exists; the caller deletes it.

    Returns:
        ``(stats, failures)``: per model ``hnn.train``'s stats (``train_loss``, ``test_loss``,
        ``test_steps``, ``seconds``: the group's seconds over its size), None for a model that
        failed; ``{index: GroupedRunFailed}``.
    """
    if not models:
        raise ValueError("train_closed_form needs at least one model")
    if len(data) != len(models) or len(seeds) != len(models) or (tests is not None and len(tests) != len(models)):
        raise ValueError(f"{len(models)} models need as many data pairs, seeds and test pairs; got {len(data)}, "
                         f"{len(seeds)} and {None if tests is None else len(tests)}")
    if total_steps < 0 or int(total_steps) != total_steps:
        raise ValueError(f"total_steps must be a non-negative integer, got {total_steps!r}")
    first = models[0]
    n = first.input_dim
    if isinstance(first, SeparableHNN):
        baseline, rows = False, None
        same = all(type(m) is type(first) and m.input_dim == n for m in models)
    else:
        baseline, rows = first.baseline, FIELD_ROWS[first.field_type]
        same = all(isinstance(m, HNN) and m.baseline == baseline and m.input_dim == n
                   and m.field_type == first.field_type for m in models)
    if not same:
        raise ValueError("a group's models must be of one kind, width and field type")
    weights = _stacked_weights(models)
    kw = dict(width=n, dtype=weights[0].dtype, device=weights[0].device)
    train_rows = GroupRows([check_data("x", x, **kw) for x, _ in data], [check_data("dxdt", y, **kw) for _, y in data],
                       batch_size, seeds, 0)
    test_rows = None if tests is None else GroupRows([check_data("test_x", x, **kw) for x, _ in tests],
                                                  [check_data("test_dxdt", y, **kw) for _, y in tests],
                                                  batch_size, seeds, 1)
    test_every = print_every if test_every is None else test_every
    names = names or [f"model {g}" for g in range(len(models))]
    optim = adam_optimizer(WeightStack(weights), learn_rate, weight_decay)

    def losses(group_rows: GroupRows, x: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
        return group_rows.loss(_field(weights, x, baseline, rows), y)

    # the loss alone is checked, not the gradient (as hnn.trainers.vmap's): the closed form's gradient is a product of
    # finite weights and bounded tanh terms, and the check would add a dozen small ops to the fast path's step
    failures, curves, seconds = group_loop(
        weights, optim, train_rows, test_rows, losses, names=names, total_steps=total_steps, test_every=test_every,
        input_noise=input_noise, label="closed-form group", progress=progress, checkpoint=checkpoint,
        checkpoint_every=checkpoint_every, after_step=after_step)

    def write_back(g: int, model) -> None:
        for j, net in enumerate(_nets(model)):
            for param, stacked in zip(_layers(net), weights):
                param.copy_(stacked[j * len(models) + g])
    return group_stats(models, failures, write_back, *curves, seconds)



def train_prepared(preps: list, checkpoint=None, names: list[str] | None = None,
                   progress: bool = False) -> tuple[list[dict | None], dict[int, GroupedRunFailed]]:
    """Train the prepared runs ``preps`` (``hnn.policy.prepare``, of one closed-form group: equal
    ``hnn.sweeps.group_runs.closed_form_key``) as one program, each ``canonical_model`` on its own rows with the run's loop
    settings; ``train_closed_form``'s ``(stats, failures)``."""
    return train_closed_form([p.canonical_model for p in preps], [(p.x, p.y) for p in preps],
                             [(p.test_x, p.test_y) for p in preps], input_noise=preps[0].specs.objective.input_noise,
                             names=names, progress=progress, checkpoint=checkpoint, **group_settings(preps))


__all__ = ["train_closed_form", "train_prepared"]
