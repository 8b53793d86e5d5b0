"""Many small models of one kind trained as one program: their parameters stacked along a leading
model axis, every product of a step one batched product over the models.

    stats, failures = hnn.grouped.fit_group(models, data, tests, seeds=[0, 1, 2, 3], total_steps=2000, ...)
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
MLP, fitting dx/dt itself (``DerivativeObjective`` without ``use_rk4``); ``group_key`` says which
configs train together. Widths group apart, not padded to the widest: a padded unit is not
exactly inert under weight decay and Adam, and from width 64 on a step is near its arithmetic
floor, so padding 16 to 64 would cost the wide step's products (benchmark ``group`` job).
"""
from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import Callable

import torch

from .errors import DivergenceError
from .kinds import get_kind
from .models.hamiltonian import FIELD_ROWS, HNN
from .models.mlp import MLP
from .objectives import DerivativeObjective
from .specs import run_specs
from .models.structured import SeparableHNN
from .models.tanh_mlp import closed_form_input_gradient, fast_tanh
from .training import (CHECKPOINT_EVERY, adam_optimizer, check_data, flushed_denormals, is_test_step, learning_rate,
                       load_checkpoint,
                       save_checkpoint, training_steps)

# the fields that must agree for configs to train as one program (seed, train_fraction and with
# them the dataset may differ)
_SHARED_FIELDS = ("input_dim", "hidden_dim", "learn_rate", "weight_decay", "batch_size", "total_steps",
                  "print_every", "field_type", "dtype", "device")


class GroupedRunFailed(DivergenceError):
    """A model of a group that failed (its loss turned NaN or infinite): its run ``name`` and ``step``. A
    ``DivergenceError``, as a lone run's non-finite loss is: a result of its config, which a rerun repeats."""

    def __init__(self, name: str, step: int, message: str):
        self.name, self.step = name, step
        super().__init__(f"{name}: {message} at step {step}; left out of its group, the others trained on")


def group_key(config) -> tuple | None:
    """Configs with equal keys can train as one group; None for a config that trains alone
    (another kind, ``use_rk4``, another nonlinearity than tanh, an objective of its own, or an
    optimizer, schedule, gradient clipping or derivative loss other than the paper's constant-rate
    Adam on the squared error, or ``balance='rms'``)."""
    if (get_kind(config.kind).grouping != "closed_form" or config.use_rk4 or config.nonlinearity != "tanh" or config.balance == "rms"
            or (config.optimizer, config.schedule, config.clip_grad, config.derivative_loss)
            != ("adam", "constant", 0.0, "l2")
            or type(config.make_objective()) is not DerivativeObjective):
        return None
    return ((type(config).__module__, type(config).__qualname__, config.kind, run_specs(config).objective.input_noise)
            + tuple(getattr(config, name) for name in _SHARED_FIELDS))


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


class GroupRows:
    """The rows each model trains on, padded to one ``(G, rows, n)`` stack, and how it draws minibatches
    (``fit_group`` and ``hnn.stacked.fit_stacked``). A model's padding repeats its first row at weight 0:
    a real state, so a model that is singular at a zero state (an LNN) sees none."""

    def __init__(self, xs, ys, batch_size, seeds, seed_offset: int):
        self.counts = [len(x) for x in xs]
        most = max(self.counts)
        self.x = torch.stack([torch.cat([x, x[:1].expand(most - len(x), -1)]) for x in xs])
        self.y = torch.stack([torch.cat([y, y[:1].expand(most - len(y), -1)]) for y in ys])
        self.batch_size = batch_size
        # CPU generators on every device: a seed draws the lone run's rows wherever the group trains
        self.gens = [torch.Generator("cpu").manual_seed(seed + seed_offset) for seed in seeds]
        sizes = [c if batch_size is None or batch_size >= c else batch_size for c in self.counts]
        self.size = max(sizes)
        # weight of each row in its model's mean: 1/(rows * width) for a drawn row, 0 for padding
        weight = torch.zeros(len(xs), self.size, dtype=self.x.dtype, device=self.x.device)
        for g, m in enumerate(sizes):
            weight[g, :m] = 1.0 / (m * self.x.shape[2])
        self.weight = weight
        self.full = all(m == c for m, c in zip(sizes, self.counts))
        self._models = torch.arange(len(xs), device=self.x.device)[:, None]

    def draw(self):
        """``(x, y)`` of this step, ``(G, size, n)`` each: the lone run's ``hnn.training.minibatch``
        of every model (its generator advances only when it draws)."""
        if self.full:
            return self.x[:, :self.size], self.y[:, :self.size], self.gens
        index = torch.zeros(len(self.gens), self.size, dtype=torch.long, device="cpu")
        for g, (gen, count) in enumerate(zip(self.gens, self.counts)):
            if self.batch_size >= count:
                index[g, :count] = torch.arange(count, device="cpu")
            else:
                index[g] = torch.randperm(count, generator=gen, device="cpu")[:self.batch_size]
        index = index.to(self.x.device)
        return self.x[self._models, index], self.y[self._models, index], self.gens

    def drawn(self) -> list[int]:
        """How many real rows each model draws a step."""
        return [c if self.batch_size is None or self.batch_size >= c else self.batch_size for c in self.counts]

    def noisy(self, xb: torch.Tensor, gens, input_noise: float) -> torch.Tensor:
        """``xb`` ``(G, size, n)`` plus each model's input noise, drawn from its generator as its lone run
        draws it (``hnn.train``): the real rows' noise only, in the CPU generator's order."""
        if not input_noise:
            return xb
        n = xb.shape[-1]
        noise = torch.stack([torch.cat([torch.randn((c, n), generator=gen, device="cpu"),
                                        torch.zeros(xb.shape[1] - c, n, device="cpu")])
                             for gen, c in zip(gens, self.drawn())])
        return xb + input_noise * noise.to(xb)

    def loss(self, prediction: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
        """Each model's mean squared error over its own rows, ``(G,)``."""
        return ((y - prediction).pow(2).sum(-1) * self.weight).sum(-1)


def fit_group(models: list[HNN], data: list[tuple], tests: list[tuple] | None = None, *, seeds: list[int],
              total_steps: int = 2000, learn_rate: float = 1e-3, weight_decay: float = 1e-4,
              batch_size: int | None = None, print_every: int = 200, test_every: int | None = None,
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
        raise ValueError("fit_group needs at least one model")
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

    # the loss alone is checked, not the gradient (as hnn.stacked's): the closed form's gradient is a product of
    # finite weights and bounded tanh terms, and the check would add a dozen small ops to the fast path's step
    failures, curves, seconds = train_steps(
        weights, optim, train_rows, test_rows, losses, names=names, total_steps=total_steps, test_every=test_every,
        input_noise=input_noise, label="group", progress=progress, checkpoint=checkpoint,
        checkpoint_every=checkpoint_every, after_step=after_step)

    def write_back(g: int, model) -> None:
        for j, net in enumerate(_nets(model)):
            for param, stacked in zip(_layers(net), weights):
                param.copy_(stacked[j * len(models) + g])
    return group_stats(models, failures, write_back, *curves, seconds)


def train_steps(weights: list[torch.Tensor], optim, train_rows: GroupRows, test_rows: GroupRows | None,
                losses: Callable[[GroupRows, torch.Tensor, torch.Tensor], torch.Tensor], *, names: list[str],
                total_steps: int, test_every: int, input_noise: float, label: str, progress: bool, checkpoint,
                checkpoint_every: float | None, learn_rate: float = 0.0, schedule: str = "constant",
                clip_grad: float = 0.0, check_gradients: bool = False, after_step=None) -> tuple[dict, tuple, float]:
    """The one training loop of a group (``fit_group`` and ``hnn.stacked.fit_stacked``): each step draws every
    model's rows and noise, sums the models' losses ``losses(rows, x, y) -> (G,)``, steps ``optim`` over the
    stacked ``weights``, drops a model whose loss (and, with ``check_gradients``, gradient) is not finite,
    records the losses and saves the checkpoint.

    Net j of model g is slice ``j * G + g`` of each weight (``hnn.stacked``'s models are one net each: slice g).
    ``schedule``, ``learn_rate``, ``clip_grad``: as ``hnn.train``'s (each model's gradient clipped to its own
    norm). Returns ``(failures, (train_loss, test_loss, test_steps), seconds)``, the losses per step ``(G,)``."""
    alive = torch.ones(len(names), dtype=torch.bool, device=weights[0].device)
    failures: dict[int, GroupedRunFailed] = {}
    curves = train_loss, test_loss, test_steps = [], [], []
    saver = GroupCheckpoint(checkpoint, weights, optim, (train_rows, test_rows), checkpoint_every, names)
    first, seconds_before = saver.resume(total_steps, alive, failures, curves)
    with flushed_denormals():
        start = time.perf_counter()
        for step in training_steps(total_steps, progress, label, start=first):
            xb, yb, gens = train_rows.draw()
            xb = train_rows.noisy(xb, gens, input_noise)
            if schedule != "constant":
                for group in optim.param_groups:
                    group["lr"] = learning_rate(learn_rate, step, total_steps, schedule)
            step_losses = losses(train_rows, xb, yb)
            # a dropped model's loss is replaced, not multiplied by 0 (NaN * 0 is NaN)
            torch.where(alive, step_losses, step_losses.new_zeros(())).sum().backward()
            finite = torch.isfinite(step_losses)
            if check_gradients:
                finite = finite & torch.stack([torch.isfinite(_per_model(w.grad, len(alive))).all(1)
                                               for w in weights]).all(0)
            if not bool(finite[alive].all()):
                _drop_failed(weights, optim, alive, finite, failures, names, step)
            if clip_grad > 0:
                _clip_each([w.grad for w in weights], clip_grad, len(alive))
            optim.step()
            optim.zero_grad(set_to_none=True)
            train_loss.append(step_losses.detach())
            if after_step is not None:
                after_step(step, weights)
            if test_rows is not None and is_test_step(step, test_every, total_steps):
                tx, ty, _ = test_rows.draw()
                with torch.no_grad():
                    test_loss.append(losses(test_rows, tx, ty))
                test_steps.append(step)
            saver.after(step, total_steps, alive, failures, curves, seconds_before + time.perf_counter() - start)
    return failures, curves, seconds_before + time.perf_counter() - start


def _per_model(w: torch.Tensor, models: int) -> torch.Tensor:
    """A stacked weight (or its gradient) as ``(models, -1)``: row g holds every slice of model g (net j of
    model g is slice ``j * models + g``; ``hnn.stacked``'s one net a model is the case j = 0)."""
    return w.reshape(-1, models, *w.shape[1:]).transpose(0, 1).reshape(models, -1)


def _clip_each(grads: list[torch.Tensor], clip: float, models: int) -> None:
    """Scale each model's slices of ``grads`` to global norm at most ``clip``, in place, as
    ``torch.nn.utils.clip_grad_norm_`` scales a lone model's."""
    norms = torch.stack([_per_model(g, models).pow(2).sum(1) for g in grads]).sum(0).sqrt()
    scale = (clip / (norms + 1e-6)).clamp(max=1.0)
    for g in grads:
        g.view(-1, models, *g.shape[1:]).mul_(scale.reshape(1, models, *[1] * (g.dim() - 1)))


def group_stats(models: list, failures: dict, write_back, train_loss: list, test_loss: list, test_steps: list,
                seconds: float) -> tuple[list[dict | None], dict]:
    """``(stats, failures)`` of a finished group: each surviving model's weights written back
    (``write_back(g, model)``, without autograd) and its ``hnn.train``-shaped stats from the per-step
    ``(G,)`` losses; None for a failed model (``fit_group`` and ``hnn.stacked.fit_stacked``)."""
    train_loss = torch.stack(train_loss).T.tolist()
    test_loss = torch.stack(test_loss).T.tolist() if test_loss else [[] for _ in models]
    stats = []
    for g, model in enumerate(models):
        if g in failures:
            stats.append(None)
            continue
        with torch.no_grad():
            write_back(g, model)
        model.eval()
        stats.append({"train_loss": train_loss[g], "test_loss": test_loss[g], "test_steps": list(test_steps),
                      "seconds": seconds / len(models), "group_seconds": seconds, "group_size": len(models)})
    return stats, failures


class WeightStack:
    """Stacked weights as ``adam_optimizer`` asks for a model's: ``parameters()`` (here and ``hnn.stacked``),
    and as a checkpoint saves and loads a model's: ``state_dict()``, ``load_state_dict()``."""

    def __init__(self, weights):
        self._weights = weights

    def parameters(self):
        return iter(self._weights)

    def state_dict(self) -> dict:
        return {"weights": [w.detach() for w in self._weights]}

    def load_state_dict(self, state: dict) -> None:
        saved = state["weights"]
        shapes, mine = [tuple(w.shape) for w in saved], [tuple(w.shape) for w in self._weights]
        if shapes != mine:
            raise ValueError(f"its stacked weights are of shapes {shapes}, this group's {mine}")
        with torch.no_grad():
            for w, value in zip(self._weights, saved):
                w.copy_(value)


class GroupCheckpoint:
    """A group's training checkpoint (``fit_group`` and ``hnn.stacked.fit_stacked``, ``checkpoint=``), as
    ``hnn.train``'s for a lone run: the stacked weights, their optimizer, every model's samplers, which
    models failed and the losses so far, saved every ``every`` seconds of training (default
    ``hnn.training.CHECKPOINT_EVERY``). Where the file exists the group resumes from it and ends with the
    floats of an unbroken group (same threads). ``path`` None: no checkpoint. ``names``: the members' run
    folders, kept in the file (``stats["names"]``) so that one no rerun forms again can be found spent
    (``hnn.sweeps.group_runs.drop_spent_checkpoints``)."""

    def __init__(self, path, weights: list, optim, rows: tuple, every: float | None = None, names: list | None = None):
        self.path, self.names = (None if path is None else Path(path)), list(names or [])
        self.stack, self.optim = WeightStack(weights), optim
        self.gens = [gen for r in rows if r is not None for gen in r.gens]
        self.every = CHECKPOINT_EVERY if every is None else every
        self.saved_at = time.perf_counter()

    def resume(self, total_steps: int, alive: torch.Tensor, failures: dict, losses: tuple) -> tuple:
        """Load the checkpoint, if there is one, into the group: ``alive``, ``failures`` and the loss lists
        ``losses = (train_loss, test_loss, test_steps)`` in place; ``(first step to run, seconds so far)``."""
        if self.path is None or not self.path.exists():
            return 0, 0.0
        first, stats, seconds = load_checkpoint(self.path, self.stack, self.optim, self.gens, total_steps)
        alive.copy_(stats["alive"])
        failures.update({g: GroupedRunFailed(self.names[g], step, "loss is not finite")
                         for g, step in stats["failed"].items()})
        train_loss, test_loss, test_steps = losses
        train_loss.extend(stats["train_loss"].unbind(0))
        test_loss.extend(stats["test_loss"].unbind(0))
        test_steps.extend(stats["test_steps"])
        print(f"resuming a group of {len(self.names)} at step {first} of {total_steps} from {self.path}", file=sys.stderr,
              flush=True)
        self.saved_at = time.perf_counter()
        return first, seconds

    def after(self, step: int, total_steps: int, alive: torch.Tensor, failures: dict, losses: tuple,
              seconds: float) -> None:
        """Save after ``step`` when ``every`` seconds have passed since the last save (never after the last)."""
        if self.path is None or step >= total_steps or time.perf_counter() - self.saved_at < self.every:
            return
        train_loss, test_loss, test_steps = losses
        none = alive.new_zeros((0, len(alive)), dtype=torch.float32)      # on the group's device, not the default
        stats = {"alive": alive.clone(), "failed": {g: f.step for g, f in failures.items()},
                 "train_loss": torch.stack(train_loss) if train_loss else none,
                 "test_loss": torch.stack(test_loss) if test_loss else none,
                 "test_steps": list(test_steps), "names": self.names}
        save_checkpoint(self.path, step, total_steps, self.stack, self.optim, self.gens, stats, seconds)
        self.saved_at = time.perf_counter()


def _drop_failed(weights, optim, alive, finite, failures, names, step) -> None:
    """Report the newly failed models by name and zero their slices (net j of model g: slice ``j * G + g``),
    after the backward of the step that found them."""
    for g in torch.nonzero(alive & ~finite).flatten().tolist():
        alive[g] = False
        failures[g] = GroupedRunFailed(names[g], step, "loss is not finite")
        print(f"  {failures[g]}", flush=True)
        with torch.no_grad():
            mine = slice(g, None, len(alive))
            for w in weights:       # weights, gradient and Adam state: its slices move no more
                w[mine] = 0
                w.grad[mine] = 0
                for value in optim.state.get(w, {}).values():
                    if torch.is_tensor(value) and value.dim() > 0:
                        value[mine] = 0


__all__ = ["GroupCheckpoint", "GroupRows", "GroupedRunFailed", "WeightStack", "fit_group", "group_key",
           "group_stats", "train_steps"]
