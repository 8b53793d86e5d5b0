"""The one training loop every task uses: minibatch steps of Adam or AdamW (constant or cosine rate)
on the L2 loss of dx/dt, or on an objective's own loss of its rows (snippets, pixel pairs, state
pairs); a test batch on a schedule, a NaN named with its step, progress (a bar, or a line now and then:
``hnn.progress``), one torch thread unless told, and a checkpoint now and then from which a killed run
resumes where it stopped, to the same floats."""
from __future__ import annotations

import contextlib
import math
import sys
import time
import warnings
from pathlib import Path
from typing import Callable, Iterable, Iterator

import numpy as np
import torch
from tqdm.auto import tqdm

from . import names
from .balance import balance_weights, weighted
from .errors import DivergenceError
from .io import atomic_write, torch_bytes
from .progress import Ticker
from .threads import torch_threads
from .units import VELOCITY_LIKE, in_canonical_units, rescale_reason


def check_data(name: str, a, width: int | None = None, dtype=torch.float32, device="cpu") -> torch.Tensor:
    """``a`` as a ``(rows, width)`` tensor, or a ValueError that names the problem and the fix."""
    t = (a if torch.is_tensor(a) else torch.as_tensor(np.asarray(a), device=device)).detach()
    if t.dim() != 2:
        raise ValueError(f"{name} must have shape (rows, dim), got {tuple(t.shape)}")
    if width is not None and t.shape[1] != width:
        raise ValueError(f"{name} has {t.shape[1]} columns but the model expects input_dim={width}; "
                         "check --input_dim against the dataset")
    if not torch.is_floating_point(t):
        t = t.to(dtype)
    bad = ~torch.isfinite(t)
    if bad.any():
        rows = torch.nonzero(bad.any(dim=1)).flatten()
        raise ValueError(f"{name} has {int(bad.sum())} NaN/inf values (first in row {int(rows[0])}, "
                         f"{len(rows)} rows affected); clean or drop those rows before training")
    return t.to(dtype=dtype, device=device)


def _checked_pair(name: str, x, dxdt, kw: dict) -> tuple[torch.Tensor, torch.Tensor]:
    """``check_data`` of states ``x`` and their targets (named ``name`` and ``d<name>/dt``), of one row count."""
    target = "dxdt" if name == "x" else f"{name.split('_')[0]}_dxdt"
    x, dxdt = check_data(name, x, **kw), check_data(target, dxdt, **kw)
    if len(x) != len(dxdt):
        raise ValueError(f"{name} has {len(x)} rows but {target} has {len(dxdt)}")
    return x, dxdt


_PROGRESS_CALLBACKS: list[Callable[[int, int], None]] = []


@contextlib.contextmanager
def report_progress(callback: Callable[[int, int], None]) -> Iterator[None]:
    """Inside this block every ``train`` call reports ``callback(steps_done, steps_total)`` after
    each optimizer step, so a caller can follow a run it starts through a task's ``train.py``
    (whose ``main(argv)`` takes no callback). The callback must be cheap: it runs every step.
    """
    _PROGRESS_CALLBACKS.append(callback)
    try:
        yield
    finally:
        _PROGRESS_CALLBACKS.remove(callback)


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


def training_steps(total_steps: int, progress: bool, desc: str = "train", start: int = 0) -> Iterable[int]:
    """The steps ``start`` .. total_steps of a training loop (the paper's loops run total_steps + 1),
    with a progress bar when ``progress``."""
    return tqdm(range(start, total_steps + 1), disable=not progress, desc=desc, leave=False,
                initial=start, total=total_steps + 1)


def is_test_step(step: int, test_every: int, total_steps: int) -> bool:
    """Whether a loop evaluates its test batch after ``step``: every ``test_every`` and the last."""
    return step % test_every == 0 or step == total_steps


# --optimizer: each name of hnn.names' list its torch.optim class
OPTIMIZERS = names.checked({"adam": torch.optim.Adam, "adamw": torch.optim.AdamW}, names.OPTIMIZERS,
                           "hnn.training.OPTIMIZERS")
SCHEDULES = names.SCHEDULES         # learning_rate's branches


def adam_optimizer(model, learn_rate: float, weight_decay: float, kind: str = "adam") -> torch.optim.Optimizer:
    """The optimizer ``train`` uses (analysis/benchmarks/benchmark.py times steps with it too): ``kind``
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


def l2_loss(predict: Callable) -> Callable:
    """``train``'s default loss: per-element squared error of ``predict(x)`` against the targets."""
    return lambda xb, yb: (yb - predict(xb)).pow(2)


def l1_loss(predict: Callable) -> Callable:
    """The LNN's loss (Cranmer et al. 2020): per-element absolute error of ``predict(x)``. The double
    pendulum's accelerations reach hundreds where its rates are large; squared, those few states
    drive every step (measured on the LNN's protocol: docs/peers.md)."""
    return lambda xb, yb: (yb - predict(xb)).abs()


# --derivative_loss: the per-element error of a fit of dx/dt, each name of hnn.names' list its function
DERIVATIVE_LOSSES = names.checked({"l2": l2_loss, "l1": l1_loss}, names.DERIVATIVE_LOSSES,
                                  "hnn.training.DERIVATIVE_LOSSES")


def batch_loss(model, loss: Callable | None = None, predict: Callable | None = None, derivative_loss: str = "l2",
               loss_weights=None, **unused) -> Callable:
    """The batch loss ``train`` minimizes, from its keyword arguments of these names (an objective's
    ``FitOptions.train_kwargs()``): ``loss`` itself, or ``fit_loss`` of the others (``unused``: the rest)."""
    return loss if loss is not None else fit_loss(model, predict, derivative_loss, loss_weights)


def fit_loss(model, predict: Callable | None = None, derivative_loss: str = "l2", loss_weights=None) -> Callable:
    """The loss ``hnn.train`` minimizes in a fit of dx/dt: ``DERIVATIVE_LOSSES[derivative_loss]`` of
    ``predict`` (default ``model.time_derivative``), each component times ``loss_weights`` ``(dim,)``
    (``hnn.balance``; None: all 1), the weights put once on the model's dtype and device."""
    loss = DERIVATIVE_LOSSES[derivative_loss](predict or model.time_derivative)
    if loss_weights is None:
        return loss
    param = next(model.parameters())
    return weighted(loss, torch.as_tensor(loss_weights, dtype=param.dtype, device=param.device))


def minibatch(x: torch.Tensor, y: torch.Tensor, batch_size: int | None, gen: torch.Generator):
    """The whole set when ``batch_size`` is None or covers it, else a random minibatch without replacement."""
    if batch_size is None or batch_size >= len(x):
        return x, y
    # drawn by the CPU generator ``gen`` on every device, so a seed picks the same rows everywhere
    ix = torch.randperm(len(x), generator=gen, device="cpu")[:batch_size].to(x.device)
    # index_select is the same gather as x[ix], and faster (docs/speed.md, "Why the fast paths")
    return x.index_select(0, ix), y.index_select(0, ix)


def optimizer_step(loss: Callable, xb: torch.Tensor, yb: torch.Tensor, optim: torch.optim.Optimizer,
                   clip_grad: float = 0.0) -> float:
    """One optimizer step on the batch; its loss. ``train`` runs this, and analysis/benchmarks/benchmark.py
    times this very function against the step's matrix-product floor. ``clip_grad`` > 0 scales the
    gradient down to that global norm first."""
    batch_loss = loss(xb, yb).mean()
    batch_loss.backward()
    if clip_grad > 0:
        torch.nn.utils.clip_grad_norm_([p for group in optim.param_groups for p in group["params"]], clip_grad)
    optim.step()
    optim.zero_grad(set_to_none=True)
    return batch_loss.item()


def _warn_off_scale(x: torch.Tensor, dxdt: torch.Tensor, model) -> None:
    """Warn when a fit of dx/dt trains on data as given that ``units='auto'`` would rescale
    (``hnn.units.rescale_reason``: the RMS of q, unless angles, of p or of either half of ``dxdt``, each over
    all of its columns, lies outside its bounds, or one part's columns spread over 10x in size). Adam's steps
    of about learn_rate and tanh's unit-wide bend suit data near unit scale: a heavy mass (p of RMS 28, dq/dt
    of 0.028) degraded a fit 40x, unwarned while only the largest column was read."""
    coordinates = "velocity" if getattr(model, "coordinates", "canonical") in VELOCITY_LIKE else "canonical"
    reason = rescale_reason(x, dxdt, bool(getattr(model, "periodic", False)), coordinates) if len(x) else None
    if reason is not None:
        warnings.warn(f"x and dxdt are {reason}; a network fits poorly there. Train hnn.units.Rescaled(model) with "
                      "units='auto' (the default), or rescale q and p so that Hamilton's equations still hold: "
                      "docs/python.md, 'Scale your states'", stacklevel=3)


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


# seconds of training between two checkpoints of a run that keeps one (``train(checkpoint=...)``): a
# killed run loses at most this much; saving a 256-wide model and its Adam moments takes milliseconds
CHECKPOINT_EVERY = 60.0
_CHECKPOINT_FORMAT = 1


def save_checkpoint(path: Path, step: int, total_steps: int, model, optim, gens, stats: dict, seconds: float):
    """Write a training loop's state after ``step`` to ``path``, atomically: ``model``'s and ``optim``'s
    ``state_dict``, the samplers ``gens`` (``torch.Generator``), the ``stats`` so far (tensors, lists and
    numbers) and the seconds trained (``train``, ``hnn.grouped.fit_group`` and ``hnn.stacked.fit_stacked``)."""
    state = {"format": _CHECKPOINT_FORMAT, "step": step, "total_steps": total_steps, "seconds": seconds,
             "model": model.state_dict(), "optim": optim.state_dict(), "gens": [g.get_state() for g in gens],
             "stats": stats}
    atomic_write(path, lambda tmp: Path(tmp).write_bytes(torch_bytes(state)))


def load_checkpoint(path: Path, model, optim, gens, total_steps: int) -> tuple[int, dict, float]:
    """Load a ``save_checkpoint`` into the model, optimizer and samplers: ``(the first step still to run, the stats
    so far, the seconds trained so far)``."""
    fix = f"delete {path} to train from the start"
    try:
        state = torch.load(path, map_location=next(model.parameters()).device, weights_only=True)
    except Exception as err:
        first_line = (str(err).splitlines() or [""])[0]
        raise ValueError(f"the training checkpoint {path} cannot be read ({type(err).__name__}: {first_line}); "
                         f"{fix}") from err
    if not isinstance(state, dict) or state.get("format") != _CHECKPOINT_FORMAT:
        raise ValueError(f"{path} is not a training checkpoint of this version of hnn; {fix}")
    if state["total_steps"] != total_steps:
        raise ValueError(f"the training checkpoint {path} is of a run of {state['total_steps']} steps, "
                         f"not {total_steps}; {fix}")
    try:
        model.load_state_dict(state["model"])
        optim.load_state_dict(state["optim"])
    except (RuntimeError, ValueError, KeyError) as err:
        raise ValueError(f"the training checkpoint {path} is of another model ({err}); {fix}") from err
    if len(state["gens"]) != len(gens):
        raise ValueError(f"the training checkpoint {path} saved {len(state['gens'])} samplers, this run draws from "
                         f"{len(gens)}; {fix}")
    for gen, saved in zip(gens, state["gens"]):
        gen.set_state(saved.cpu())      # the samplers draw on the CPU whatever the model's device
    return state["step"] + 1, state["stats"], state["seconds"]


def train(model, x, dxdt, test_x=None, test_dxdt=None, *, total_steps: int = 2000, learn_rate: float = 1e-3,
          weight_decay: float = 1e-4, batch_size: int | None = None, seed: int = 0, print_every: int = 200,
          verbose: bool = False, test_every: int | None = None, input_noise: float = 0.0,
          predict: Callable | None = None, loss: Callable | None = None, progress: bool | None = None,
          optimizer: str = "adam", schedule: str = "constant", clip_grad: float = 0.0,
          derivative_loss: str = "l2", loss_weights=None, checkpoint: str | Path | None = None,
          checkpoint_every: float | None = None, generators: tuple = (), balance: str = "auto",
          units: str = "auto", threads: int | None = 1) -> dict:
    """Fit ``model.time_derivative`` to ``dxdt`` (or minimize ``loss``) with ``optimizer``; returns the stats.

    Runs ``total_steps + 1`` optimizer steps, as the original. Full batch when ``batch_size``
    is None, else a fresh random minibatch (without replacement) each step, with a test batch
    of the same size. The test loss is measured every ``test_every`` steps (default
    ``print_every``) and at the last step, without the double-backward graph: the original
    measured it every step with that graph, which was a third of its training time.

    Args:
        x, dxdt: training states and their time derivatives, ``(rows, dim)``, arrays or tensors.
        test_x, test_dxdt: optional held-out pair of the same width.
        seed: seeds the minibatch sampler and the input noise (the model's init is seeded by its
            builder).
        input_noise: std of Gaussian noise added to each training batch's inputs x, fresh each
            step (0: none). The original 2-body script added it to the prediction instead.
        predict: ``x -> prediction`` compared with ``dxdt``; default ``model.time_derivative``.
        loss: ``(x, y) -> per-sample or scalar loss`` replacing the L2 loss of ``predict``, for
            models with an objective of their own (the pixel task passes ``x``, ``x_next``; the
            trajectory objective flattened snippets). Its arrays' widths are then not checked
            against the model's ``input_dim``: the loss reads them. A ``loss`` with an ``after_training(x, y)``
            method gets the training arrays once the fit ends (a learned map's warning where it ends no better
            than the identity: ``hnn.objectives.map.MapObjective.loss_for``).
        progress: None (default): a bar where someone watches (a terminal or a notebook; it appears
            after 2 s, so a short fit stays silent), else a line on stderr every 10 s (``'train: step
            400 of 2001, about 1 min left'``); nothing with ``verbose`` (its own lines) or inside
            ``report_progress`` (its caller shows progress its own way). False: nothing; True: a bar.
        optimizer, schedule: ``adam_optimizer``'s kind and ``learning_rate``'s schedule.
        clip_grad: clip each step's gradient to this global norm (0: never).
        derivative_loss: the per-element error of the default loss (``DERIVATIVE_LOSSES``): ``'l2'``
            squared (the paper's), ``'l1'`` absolute (the LNN's); a custom ``loss`` replaces both.
        loss_weights: ``(dim,)`` weights of the default loss's components (``hnn.balance``); None: those
            ``balance`` gives.
        balance: where ``loss_weights`` is None, the weights of a fit of dx/dt by ``hnn.balance``'s rule, as
            a run's ``--balance``: ``'auto'`` (each component by its RMS over ``dxdt`` where the largest
            exceeds the smallest over 10x, else the plain loss), ``'rms'`` (always) or ``'off'`` (never).
        units: the units a fit of dx/dt (no ``loss``, no ``predict``) trains in, as a run's ``--units``
            (``hnn.units``): an ``hnn.units.Rescaled`` model without scales gets them here from ``x`` and
            ``dxdt`` (``'auto'``: where ``hnn.units.rescale_reason`` finds a reason, their sizes outside its
            bounds or one part's columns spread over 10x; ``'on'``: always; ``'off'``: never), its inner model
            trains in those canonical units (the loss history too) and it answers in the user's; a plain model on data ``'auto'`` would rescale is refused
            with the fix (wrap it in ``Rescaled``, or pass ``units='off'``). ``'off'`` trains as given,
            with a warning where the data lie far from unit scale.
        checkpoint: a file where the loop saves its state (weights, optimizer, samplers, stats) every
            ``checkpoint_every`` seconds of training (default ``CHECKPOINT_EVERY``); where the file
            exists, training resumes from it and ends with the floats of an uninterrupted run (at the
            same torch threads). The caller deletes it once the run is saved (``hnn.run_experiment``
            keeps one per run).
        generators: the ``torch.Generator`` objects a custom ``loss`` draws from (its noise, say),
            which the checkpoint saves and restores with the loop's own samplers.
        threads: torch's thread count while it trains (default 1, as every ``train.py``: beside other
            work a second thread slows a fit many times over, docs/speed.md#threads); the caller's count
            is restored after, however the fit ends. None: the caller's count as it is.

    Returns:
        ``{'train_loss': [...], 'test_loss': [...], 'test_steps': [...], 'seconds': float}``:
        one train loss per step, and the test losses at ``test_steps`` (empty without test data);
        ``'test_diverged'`` (``[{'step', 'why'}]``) where a test batch before the last raised
        ``DivergenceError``, which training goes on past (at the last step it fails the run);
        ``'loss_weights'`` where ``balance`` weighed the loss and ``'unit_scales'`` where ``units``
        rescaled the fit (what each resolved to).
    """
    if total_steps < 0 or int(total_steps) != total_steps:
        raise ValueError(f"total_steps must be a non-negative integer, got {total_steps!r}")
    if not input_noise >= 0:
        raise ValueError(f"input_noise must be a non-negative std, got {input_noise!r}")
    if batch_size is not None and batch_size < 1:
        raise ValueError(f"batch_size must be positive or None (full batch), got {batch_size!r}")
    param = next(model.parameters())
    # a custom loss owns its arrays' layout (e.g. flattened trajectory snippets): rows, not widths, are checked
    width = getattr(model, "input_dim", None) if loss is None else None
    kw = dict(width=width, dtype=param.dtype, device=param.device)
    has_test = test_x is not None
    given = (x, dxdt, test_x, test_dxdt)
    x, dxdt = _checked_pair("x", x, dxdt, kw)
    if has_test:
        test_x, test_dxdt = _checked_pair("test_x", test_x, test_dxdt, kw)
    if derivative_loss not in DERIVATIVE_LOSSES:
        raise ValueError(f"derivative_loss={derivative_loss!r}: choose one of {', '.join(DERIVATIVE_LOSSES)}")
    resolved = {}
    if loss is None and predict is None:        # a fit of dx/dt itself, in the units of ``units``
        fitted, *arrays = in_canonical_units(model, units, *given)     # hnn.fit_least_squares' rule too
        if fitted is not model:     # a Rescaled model: its inner trains on the arrays in its canonical units
            resolved["unit_scales"] = model.scales.to_dict()
            model, param = fitted, next(fitted.parameters())
            x, dxdt = _checked_pair("x", arrays[0], arrays[1], kw)
            if has_test:
                test_x, test_dxdt = _checked_pair("test_x", arrays[2], arrays[3], kw)
    if loss is None:        # a fit of dx/dt: its arrays are states and their derivatives
        if loss_weights is None:
            loss_weights = balance_weights(dxdt, balance, derivative_loss)
            if loss_weights is not None:
                resolved["loss_weights"] = [float(w) for w in loss_weights]
        if "unit_scales" not in resolved:
            _warn_off_scale(x, dxdt, model)
        loss = fit_loss(model, predict, derivative_loss, loss_weights)
    if test_every is None:
        test_every = print_every
    if test_every < 1 or print_every < 1:
        raise ValueError(f"print_every and test_every must be positive, got {print_every}, {test_every}")
    if not clip_grad >= 0:
        raise ValueError(f"clip_grad must be a non-negative norm (0: no clipping), got {clip_grad!r}")
    learning_rate(learn_rate, 0, total_steps, schedule)         # an unknown schedule fails before training
    optim = adam_optimizer(model, learn_rate, weight_decay, optimizer)
    gen = torch.Generator("cpu").manual_seed(seed)
    test_gen = torch.Generator("cpu").manual_seed(seed + 1)
    stats = {"train_loss": [], "test_loss": [], "test_steps": [], **resolved}
    first, seconds_before = 0, 0.0
    checkpoint_every = CHECKPOINT_EVERY if checkpoint_every is None else checkpoint_every
    if checkpoint is not None:
        checkpoint = Path(checkpoint)
        if checkpoint.exists():
            first, stats, seconds_before = load_checkpoint(checkpoint, model, optim, (gen, test_gen, *generators),
                                                   total_steps)
            print(f"resuming at step {first} of {total_steps} from {checkpoint}", file=sys.stderr, flush=True)
    callbacks = list(_PROGRESS_CALLBACKS)
    if progress is None and (verbose or callbacks):     # its own lines, or a report_progress caller's display
        progress = False
    model.train()
    with torch_threads(threads), flushed_denormals(), Ticker(total_steps + 1, "train", progress, first) as tick:
        start = saved_at = time.perf_counter()
        for step in range(first, total_steps + 1):
            xb, yb = minibatch(x, dxdt, batch_size, gen)
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
            for callback in callbacks:
                callback(step + 1, total_steps + 1)
            tick.advance()
            if has_test and is_test_step(step, test_every, total_steps):
                tx, ty = minibatch(test_x, test_dxdt, batch_size, test_gen)
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
                save_checkpoint(checkpoint, step, total_steps, model, optim, (gen, test_gen, *generators), stats,
                                 seconds_before + time.perf_counter() - start)
                saved_at = time.perf_counter()
    model.eval()
    stats["seconds"] = seconds_before + time.perf_counter() - start
    if hasattr(loss, "after_training"):     # a custom loss's check of the fit on its own rows (a learned map's)
        loss.after_training(x, dxdt)
    return stats
