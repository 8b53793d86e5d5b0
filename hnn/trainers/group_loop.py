"""The group loop: many models' stacked weights trained as one program (``group_loop``), each model with
what its lone run has (its rows and samplers: ``hnn.trainers.rows.GroupRows``, its Adam state, its
clipping), a model whose loss turns NaN or infinite named and dropped while the others go on
(``GroupedRunFailed``), the group's checkpoint (``GroupCheckpoint``) and each model's stats
(``group_stats``). Both group trainers run it: ``hnn.trainers.closed_form`` and ``hnn.trainers.vmap``."""
from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import Callable

import torch

from ..errors import DivergenceError
from ..progress import Ticker
from . import checkpoint as checkpoints
from .loop import flushed_denormals, is_test_step, learning_rate
from .rows import GroupRows


class GroupedRunFailed(DivergenceError):
    """A model of a group that failed (its loss turned NaN or infinite): its run ``name`` and ``step``. A
    ``DivergenceError``, as a lone run's non-finite loss is: a result of its config, which a rerun repeats."""

    def __init__(self, name: str, step: int, message: str):
        self.name, self.step = name, step
        super().__init__(f"{name}: {message} at step {step}; left out of its group, the others trained on")


def group_loop(weights: list[torch.Tensor], optim, train_rows: GroupRows, test_rows: GroupRows | None,
                losses: Callable[[GroupRows, torch.Tensor, torch.Tensor], torch.Tensor], *, names: list[str],
                total_steps: int, test_every: int, input_noise: float, label: str, progress: bool, checkpoint,
                checkpoint_every: float | None, learn_rate: float = 0.0, schedule: str = "constant",
                clip_grad: float = 0.0, check_gradients: bool = False, after_step=None) -> tuple[dict, tuple, float]:
    """The one training loop of a group (``hnn.trainers.closed_form.train_closed_form`` and ``hnn.trainers.vmap.train_vmap``): each step draws every
    model's rows and noise, sums the models' losses ``losses(rows, x, y) -> (G,)``, steps ``optim`` over the
    stacked ``weights``, drops a model whose loss (and, with ``check_gradients``, gradient) is not finite,
    records the losses and saves the checkpoint.

    Net j of model g is slice ``j * G + g`` of each weight (``hnn.trainers.vmap``'s models are one net each: slice g).
    ``schedule``, ``learn_rate``, ``clip_grad``: as ``hnn.train``'s (each model's gradient clipped to its own
    norm). Returns ``(failures, (train_loss, test_loss, test_steps), seconds)``, the losses per step ``(G,)``."""
    alive = torch.ones(len(names), dtype=torch.bool, device=weights[0].device)
    failures: dict[int, GroupedRunFailed] = {}
    curves = train_loss, test_loss, test_steps = [], [], []
    saver = GroupCheckpoint(checkpoint, weights, optim, (train_rows, test_rows), checkpoint_every, names)
    first, seconds_before = saver.resume(total_steps, alive, failures, curves)
    with flushed_denormals(), Ticker(total_steps + 1, label, progress, first) as tick:
        start = time.perf_counter()
        for step in range(first, total_steps + 1):
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
            tick.advance()
            saver.after(step, total_steps, alive, failures, curves, seconds_before + time.perf_counter() - start)
    return failures, curves, seconds_before + time.perf_counter() - start


def group_settings(preps: list) -> dict:
    """The loop settings a group of prepared runs (``hnn.policy.prepare``) shares, from the first one's
    ``TrainingSpec`` (a group's key makes them equal), and each member's seed: the keywords of both group
    trainers of these names."""
    first = preps[0].specs.training
    return dict(seeds=[p.specs.training.seed for p in preps], total_steps=first.total_steps,
                learn_rate=first.learn_rate, weight_decay=first.weight_decay, batch_size=first.batch_size,
                print_every=first.print_every)


def _per_model(w: torch.Tensor, models: int) -> torch.Tensor:
    """A stacked weight (or its gradient) as ``(models, -1)``: row g holds every slice of model g (net j of
    model g is slice ``j * models + g``; ``hnn.trainers.vmap``'s one net a model is the case j = 0)."""
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
    ``(G,)`` losses; None for a failed model (``hnn.trainers.closed_form.train_closed_form`` and ``hnn.trainers.vmap.train_vmap``)."""
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
    """Stacked weights as ``adam_optimizer`` asks for a model's: ``parameters()`` (both group trainers),
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
    """A group's training checkpoint (both group trainers' ``checkpoint=``), as
    ``hnn.train``'s for a lone run: the stacked weights, their optimizer, every model's samplers, which
    models failed and the losses so far, saved every ``every`` seconds of training (default
    ``hnn.trainers.checkpoint.CHECKPOINT_EVERY``). Where the file exists the group resumes from it and ends with the
    floats of an unbroken group (same threads). ``path`` None: no checkpoint. ``names``: the members' run
    folders, kept in the file (``stats["names"]``) so that one no rerun forms again can be found spent
    (``hnn.sweeps.group_runs.drop_spent_checkpoints``)."""

    def __init__(self, path, weights: list, optim, rows: tuple, every: float | None = None, names: list | None = None):
        self.path, self.names = (None if path is None else Path(path)), list(names or [])
        self.stack, self.optim = WeightStack(weights), optim
        self.gens = [gen for r in rows if r is not None for gen in r.gens]
        self.every = every
        self.saved_at = time.perf_counter()

    def resume(self, total_steps: int, alive: torch.Tensor, failures: dict, losses: tuple) -> tuple:
        """Load the checkpoint, if there is one, into the group: ``alive``, ``failures`` and the loss lists
        ``losses = (train_loss, test_loss, test_steps)`` in place; ``(first step to run, seconds so far)``."""
        if self.path is None or not self.path.exists():
            return 0, 0.0
        first, stats, seconds = checkpoints.load_checkpoint(self.path, self.stack, self.optim, self.gens, total_steps)
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
        every = checkpoints.CHECKPOINT_EVERY if self.every is None else self.every
        if self.path is None or step >= total_steps or time.perf_counter() - self.saved_at < every:
            return
        train_loss, test_loss, test_steps = losses
        none = alive.new_zeros((0, len(alive)), dtype=torch.float32)      # on the group's device, not the default
        stats = {"alive": alive.clone(), "failed": {g: f.step for g, f in failures.items()},
                 "train_loss": torch.stack(train_loss) if train_loss else none,
                 "test_loss": torch.stack(test_loss) if test_loss else none,
                 "test_steps": list(test_steps), "names": self.names}
        checkpoints.save_checkpoint(self.path, step, total_steps, self.stack, self.optim, self.gens, stats, seconds)
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
