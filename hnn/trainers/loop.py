"""The lone loop: minibatch steps of Adam or AdamW (constant or cosine rate) on a batch loss, a test batch
on a schedule, a NaN named with its step, one progress reporter (``hnn.progress.Ticker``), torch's thread
count for the loop, and a checkpoint now and then (``hnn.trainers.checkpoint``) from which a killed run
resumes where it stopped, to the same floats. It takes tensors and a loss already decided: the checks of
the user's arrays, their units and the loss's balance are the callers' (``hnn.train``, a prepared run)."""
from __future__ import annotations

import contextlib
import math
import sys
import time
from pathlib import Path
from typing import Callable, Iterator

import torch

from .. import names
from ..errors import DivergenceError
from ..progress import Ticker
from ..settings import RunSettings
from ..threads import torch_threads
from . import checkpoint as checkpoints
from .rows import minibatch


def flushes_denormals() -> bool:
    """Whether this thread's float arithmetic flushes denormals to zero now (torch has no getter)."""
    tiny = torch.full((1,), torch.finfo(torch.float32).tiny, device="cpu")    # the smallest normal float32
    return bool((tiny / 2 == 0).item())                          # half of it is denormal, or 0 when flushed


@contextlib.contextmanager
def flushed_denormals() -> Iterator[None]:
    """Inside this block float arithmetic flushes denormals to zero; the caller's setting after.

    Weights that only weight decay moves (e.g. those of pixels that are always dark) shrink into
    denormal floats, and CPU arithmetic on denormals is many times slower (the pixel task slowed
    over 3x by step 3000: docs/speed.md): both training loops run inside it."""
    was_flushing = flushes_denormals()
    torch.set_flush_denormal(True)
    try:
        yield
    finally:
        torch.set_flush_denormal(was_flushing)


def is_test_step(step: int, test_every: int, total_steps: int) -> bool:
    """Whether a loop evaluates its test batch after ``step``: every ``test_every`` and the last."""
    return step % test_every == 0 or step == total_steps


# --optimizer: each name of hnn.names' list its torch.optim class
OPTIMIZERS = names.checked({"adam": torch.optim.Adam, "adamw": torch.optim.AdamW}, names.OPTIMIZERS,
                           "hnn.trainers.loop.OPTIMIZERS")
SCHEDULES = names.SCHEDULES         # learning_rate's branches


def adam_optimizer(model, learn_rate: float, weight_decay: float, kind: str = "adam") -> torch.optim.Optimizer:
    """The optimizer every trainer uses (analysis/benchmarks/benchmark.py times steps with it too): ``kind``
    ``'adam'`` adds ``weight_decay * w`` to the gradient (the paper's), ``'adamw'`` decays the
    weights apart from the gradient's moments (decoupled, Loshchilov & Hutter; CHNN's)."""
    if kind not in OPTIMIZERS:
        raise ValueError(f"optimizer={kind!r}: choose one of {', '.join(OPTIMIZERS)}")
    device = next(model.parameters()).device
    # the fused kernel updates all parameters in one pass, cheaper than the foreach one (docs/speed.md)
    return OPTIMIZERS[kind](model.parameters(), lr=learn_rate, weight_decay=weight_decay,
                            fused=device.type in ("cpu", "cuda"))


def learning_rate(learn_rate: float, step: int, total_steps: int, schedule: str = "constant") -> float:
    """The rate of optimizer step ``step`` (0 .. total_steps): ``'constant'``, or ``'cosine'``
    annealing from ``learn_rate`` at step 0 to 0 at step ``total_steps``."""
    if schedule == "constant":
        return learn_rate
    if schedule == "cosine":
        return 0.5 * learn_rate * (1.0 + math.cos(math.pi * step / max(total_steps, 1)))
    raise ValueError(f"schedule={schedule!r}: choose one of {', '.join(SCHEDULES)}")


def optimizer_step(loss: Callable, xb: torch.Tensor, yb: torch.Tensor, optim: torch.optim.Optimizer,
                   clip_grad: float = 0.0) -> float:
    """One optimizer step on the batch; its loss. ``run_loop`` runs this, and analysis/benchmarks/benchmark.py
    times this very function against the step's matrix-product floor. ``clip_grad`` > 0 scales the
    gradient down to that global norm first."""
    batch_loss = loss(xb, yb).mean()
    batch_loss.backward()
    if clip_grad > 0:
        torch.nn.utils.clip_grad_norm_([p for group in optim.param_groups for p in group["params"]], clip_grad)
    optim.step()
    optim.zero_grad(set_to_none=True)
    return batch_loss.item()


def check_loop(total_steps: int, input_noise: float, batch_size: int | None, print_every: int,
               test_every: int | None, clip_grad: float, learn_rate: float, schedule: str) -> int:
    """Check a loop's settings before anything trains (a ValueError naming the value and the fix); the
    test interval (``test_every``, default ``print_every``)."""
    if total_steps < 0 or int(total_steps) != total_steps:
        raise ValueError(f"total_steps must be a non-negative integer, got {total_steps!r}")
    if not input_noise >= 0:
        raise ValueError(f"input_noise must be a non-negative std, got {input_noise!r}")
    if batch_size is not None and batch_size < 1:
        raise ValueError(f"batch_size must be positive or None (full batch), got {batch_size!r}")
    test_every = print_every if test_every is None else test_every
    if test_every < 1 or print_every < 1:
        raise ValueError(f"print_every and test_every must be positive, got {print_every}, {test_every}")
    if not clip_grad >= 0:
        raise ValueError(f"clip_grad must be a non-negative norm (0: no clipping), got {clip_grad!r}")
    learning_rate(learn_rate, 0, total_steps, schedule)         # an unknown schedule fails before training
    return test_every


def _test_diverged(stats: dict, step: int, err: DivergenceError) -> None:
    """Record a test batch that diverged after ``step``, before the last (``stats["test_diverged"]``: the
    step and why) and say so on stderr the first time: training goes on, the test loss skips that step."""
    message = err.args[0] if err.args else str(err)
    if not stats.get("test_diverged"):
        print(f"warning: {message.rstrip('.')}; training goes on (the test loss skips a step whose test batch diverged, "
              "and a run whose last test batch diverges fails)", file=sys.stderr, flush=True)
    stats.setdefault("test_diverged", []).append({"step": step, "why": message})


def _say_when(err: DivergenceError, when: str) -> None:
    """Prefix ``err``'s message (its first argument) with where in the loop the model failed."""
    err.args = (f"at {when}: {err.args[0] if err.args else err}",) + err.args[1:]


def run_loop(model, loss: Callable, x: torch.Tensor, y: torch.Tensor, test_x: torch.Tensor | None = None,
             test_y: torch.Tensor | None = None, *, total_steps: int = RunSettings.total_steps,
             learn_rate: float = RunSettings.learn_rate, weight_decay: float = RunSettings.weight_decay,
             batch_size: int | None = RunSettings.batch_size, seed: int = RunSettings.seed,
             print_every: int = RunSettings.print_every, verbose: bool = RunSettings.verbose,
             test_every: int | None = None, input_noise: float = 0.0, optimizer: str = RunSettings.optimizer,
             schedule: str = RunSettings.schedule, clip_grad: float = RunSettings.clip_grad,
             checkpoint: str | Path | None = None, checkpoint_every: float | None = None, generators: tuple = (),
             threads: int | None = 1, progress: bool | None = None, on_step: Callable[[int, int], None] | None = None,
             resolved: dict | None = None) -> dict:
    """Minimize ``loss(xb, yb)`` (per row or element; its mean a step) over ``model``'s parameters on the
    checked tensors ``x``, ``y`` ``(rows, ...)`` (and the test pair): ``total_steps + 1`` steps, as the
    original; returns the stats (``hnn.train``'s, with ``resolved``'s entries: what the caller decided).

    ``on_step(steps_done, steps_total)`` after each optimizer step (a caller that follows or stops a run:
    raising from it stops the loop); ``progress`` as ``hnn.progress.Ticker``'s. The other arguments are
    ``hnn.train``'s."""
    test_every = check_loop(total_steps, input_noise, batch_size, print_every, test_every, clip_grad, learn_rate,
                            schedule)
    has_test = test_x is not None
    optim = adam_optimizer(model, learn_rate, weight_decay, optimizer)
    gen = torch.Generator("cpu").manual_seed(seed)
    test_gen = torch.Generator("cpu").manual_seed(seed + 1)
    stats = {"train_loss": [], "test_loss": [], "test_steps": [], **(resolved or {})}
    first, seconds_before = 0, 0.0
    checkpoint_every = checkpoints.CHECKPOINT_EVERY if checkpoint_every is None else checkpoint_every
    if checkpoint is not None:
        checkpoint = Path(checkpoint)
        if checkpoint.exists():
            first, stats, seconds_before = checkpoints.load_checkpoint(checkpoint, model, optim,
                                                                       (gen, test_gen, *generators), total_steps)
            print(f"resuming at step {first} of {total_steps} from {checkpoint}", file=sys.stderr, flush=True)
    model.train()
    with torch_threads(threads), flushed_denormals(), Ticker(total_steps + 1, "train", progress, first) as tick:
        start = saved_at = time.perf_counter()
        for step in range(first, total_steps + 1):
            xb, yb = minibatch(x, y, batch_size, gen)
            if input_noise:
                xb = xb + input_noise * torch.randn(xb.shape, generator=gen, device="cpu").to(xb)
            if schedule != "constant":
                for group in optim.param_groups:
                    group["lr"] = learning_rate(learn_rate, step, total_steps, schedule)
            try:
                stats["train_loss"].append(optimizer_step(loss, xb, yb, optim, clip_grad))
            except DivergenceError as err:      # the model's own field failed (a singular L, say): say when
                _say_when(err, f"training step {step} of {total_steps}")
                raise
            if not math.isfinite(stats["train_loss"][-1]):
                raise DivergenceError(f"the training loss is {stats['train_loss'][-1]} at step {step} of "
                                      f"{total_steps}; the model's weights are no longer finite. Lower --learn_rate, "
                                      "set --clip_grad (e.g. 1.0) or train in --dtype float64")
            if on_step is not None:
                on_step(step + 1, total_steps + 1)
            tick.advance()
            if has_test and is_test_step(step, test_every, total_steps):
                tx, ty = minibatch(test_x, test_y, batch_size, test_gen)
                try:
                    with torch.no_grad():
                        stats["test_loss"].append(loss(tx, ty).mean().item())
                    stats["test_steps"].append(step)
                except DivergenceError as err:
                    _say_when(err, f"the test batch after training step {step} of {total_steps}")
                    if step == total_steps:     # the trained model fails on held-out states: the run failed
                        raise
                    # before the end a test batch only watches: the weights are finite (the training loss
                    # was), and an early field may still run off on a held-out state that training fixes
                    _test_diverged(stats, step, err)
            if verbose and step % print_every == 0:
                test = (f", test_loss {stats['test_loss'][-1]:.4e}" if stats["test_steps"][-1:] == [step]
                        else ", test batch diverged" if stats.get("test_diverged", [{}])[-1].get("step") == step
                        else "") if has_test else ""
                print(f"step {step}, train_loss {stats['train_loss'][-1]:.4e}{test}", flush=True)
            if checkpoint is not None and step < total_steps and time.perf_counter() - saved_at >= checkpoint_every:
                checkpoints.save_checkpoint(checkpoint, step, total_steps, model, optim, (gen, test_gen, *generators),
                                            stats, seconds_before + time.perf_counter() - start)
                saved_at = time.perf_counter()
    model.eval()
    stats["seconds"] = seconds_before + time.perf_counter() - start
    if hasattr(loss, "after_training"):     # a custom loss's check of the fit on its own rows (a learned map's)
        loss.after_training(x, y)
    return stats
