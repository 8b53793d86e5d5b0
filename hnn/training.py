"""``hnn.train``, the front door of the lone loop for a user's arrays: it checks them, decides the units a
fit of dx/dt trains in and the balance of its loss (``hnn.units``, ``hnn.balance``), builds the loss
(``DERIVATIVE_LOSSES``) and hands the loop (``hnn.trainers.loop.run_loop``) tensors and a loss. A saved
run's lone member of the family (``hnn.trainers.lone``) hands it a prepared run's instead."""
from __future__ import annotations

from pathlib import Path
from typing import Callable

import torch

from . import names
from .balance import balance_weights, weighted
from .settings import RunSettings
from .trainers.loop import check_loop, run_loop
from .trainers.rows import checked_pair, warn_off_scale
from .units import in_canonical_units


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
    ``LoopOptions.train_kwargs()``): ``loss`` itself, or ``dxdt_loss`` of the others (``unused``: the rest)."""
    return loss if loss is not None else dxdt_loss(model, predict, derivative_loss, loss_weights)


def dxdt_loss(model, predict: Callable | None = None, derivative_loss: str = "l2", loss_weights=None) -> Callable:
    """The loss ``hnn.train`` minimizes in a fit of dx/dt: ``DERIVATIVE_LOSSES[derivative_loss]`` of
    ``predict`` (default ``model.time_derivative``), each component times ``loss_weights`` ``(dim,)``
    (``hnn.balance``; None: all 1), the weights put once on the model's dtype and device."""
    loss = DERIVATIVE_LOSSES[derivative_loss](predict or model.time_derivative)
    if loss_weights is None:
        return loss
    param = next(model.parameters())
    return weighted(loss, torch.as_tensor(loss_weights, dtype=param.dtype, device=param.device))


def train(model, x, dxdt, test_x=None, test_dxdt=None, *, total_steps: int = RunSettings.total_steps,
          learn_rate: float = RunSettings.learn_rate, weight_decay: float = RunSettings.weight_decay,
          batch_size: int | None = RunSettings.batch_size, seed: int = RunSettings.seed,
          print_every: int = RunSettings.print_every, verbose: bool = RunSettings.verbose,
          test_every: int | None = None, input_noise: float = 0.0,
          predict: Callable | None = None, loss: Callable | None = None, progress: bool | None = None,
          optimizer: str = RunSettings.optimizer, schedule: str = RunSettings.schedule,
          clip_grad: float = RunSettings.clip_grad, derivative_loss: str = RunSettings.derivative_loss,
          loss_weights=None, checkpoint: str | Path | None = None, checkpoint_every: float | None = None,
          generators: tuple = (), balance: str = RunSettings.balance, units: str = RunSettings.units,
          threads: int | None = RunSettings.threads, on_step: Callable[[int, int], None] | None = None) -> dict:
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
            400 of 2001, about 1 min left'``); nothing with ``verbose`` (its own lines) or with
            ``on_step`` (its caller shows progress its own way). False: nothing; True: a bar.
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
        on_step: ``on_step(steps_done, steps_total)`` after each optimizer step, so a caller can follow the
            fit (or stop it by raising); it must be cheap: it runs every step.

    Returns:
        ``{'train_loss': [...], 'test_loss': [...], 'test_steps': [...], 'seconds': float}``:
        one train loss per step, and the test losses at ``test_steps`` (empty without test data);
        ``'test_diverged'`` (``[{'step', 'why'}]``) where a test batch before the last raised
        ``DivergenceError``, which training goes on past (at the last step it fails the run);
        ``'loss_weights'`` where ``balance`` weighed the loss and ``'unit_scales'`` where ``units``
        rescaled the fit (what each resolved to).
    """
    # the loop's settings fail before anything is built or rescaled
    check_loop(total_steps, input_noise, batch_size, print_every, test_every, clip_grad, learn_rate, schedule)
    if progress is None and (verbose or on_step is not None):     # its own lines, or its caller's display
        progress = False
    param = next(model.parameters())
    # a custom loss owns its arrays' layout (e.g. flattened trajectory snippets): rows, not widths, are checked
    width = getattr(model, "input_dim", None) if loss is None else None
    kw = dict(width=width, dtype=param.dtype, device=param.device)
    has_test = test_x is not None
    given = (x, dxdt, test_x, test_dxdt)
    x, dxdt = checked_pair("x", x, dxdt, kw)
    if has_test:
        test_x, test_dxdt = checked_pair("test_x", test_x, test_dxdt, kw)
    if derivative_loss not in DERIVATIVE_LOSSES:
        raise ValueError(f"derivative_loss={derivative_loss!r}: choose one of {', '.join(DERIVATIVE_LOSSES)}")
    resolved = {}
    if loss is None and predict is None:        # a fit of dx/dt itself, in the units of ``units``
        fitted, *arrays = in_canonical_units(model, units, *given)     # hnn.fit_least_squares' rule too
        if fitted is not model:     # a Rescaled model: its inner trains on the arrays in its canonical units
            resolved["unit_scales"] = model.scales.to_dict()
            model, param = fitted, next(fitted.parameters())
            x, dxdt = checked_pair("x", arrays[0], arrays[1], kw)
            if has_test:
                test_x, test_dxdt = checked_pair("test_x", arrays[2], arrays[3], kw)
    if loss is None:        # a fit of dx/dt: its arrays are states and their derivatives
        if loss_weights is None:
            loss_weights = balance_weights(dxdt, balance, derivative_loss)
            if loss_weights is not None:
                resolved["loss_weights"] = [float(w) for w in loss_weights]
        if "unit_scales" not in resolved:
            warn_off_scale(x, dxdt, model)
        loss = dxdt_loss(model, predict, derivative_loss, loss_weights)
    return run_loop(model, loss, x, dxdt, test_x if has_test else None, test_dxdt if has_test else None,
                    total_steps=total_steps, learn_rate=learn_rate, weight_decay=weight_decay, batch_size=batch_size,
                    seed=seed, print_every=print_every, verbose=verbose, test_every=test_every,
                    input_noise=input_noise, optimizer=optimizer, schedule=schedule, clip_grad=clip_grad,
                    checkpoint=checkpoint, checkpoint_every=checkpoint_every, generators=generators,
                    threads=threads, progress=progress, on_step=on_step, resolved=resolved)
