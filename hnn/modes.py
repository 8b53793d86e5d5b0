"""Modes that a caller sets and a lower layer reads, without either importing the other: ``frozen_weights``
(a rollout promises that no weight changes, so a model may evaluate its field through kernels built
once per rollout) and ``model_axis`` (a group of models runs under ``torch.func.vmap`` over a
leading model axis: input gradients take ``torch.func.grad``, and checks that read a value are left
to the group's trainer, which checks each model's loss).

    with torch.no_grad(), hnn.modes.frozen_weights():     # as hnn.rollout does
        dxdt = model.time_derivative(x)                    # the model may use a cached kernel
"""
from __future__ import annotations

import contextlib
import threading


class _Modes(threading.local):
    """Each thread's modes. The defaults are class attributes: a rollout reads them at every field call,
    and ``getattr(local, name, default)`` of a name never set raises and catches inside (1-1.5 us)."""
    kernels: dict | None = None     # {(id(owner), key): (owner, kernel)} inside frozen_weights
    model_axis: bool = False


_frozen = _Modes()


@contextlib.contextmanager
def frozen_weights():
    """Within this context the models' weights do not change, so their fields may run as kernels
    built once (``hnn.rollout`` runs a non-differentiable rollout in it). Nested contexts share the
    outer one's kernels; leaving the outermost drops them."""
    outer = _frozen.kernels
    if outer is None:
        _frozen.kernels = {}
    try:
        yield
    finally:
        if outer is None:
            _frozen.kernels = None


def frozen_kernels() -> dict | None:
    """The kernel cache of the current ``frozen_weights`` context (``{(id(owner), key): (owner,
    kernel)}``, the models' to fill), or None outside one."""
    return _frozen.kernels


@contextlib.contextmanager
def model_axis():
    """Within this context models run under ``torch.func.vmap`` over a model axis (``hnn.trainers.vmap``):
    ``torch.autograd.grad`` does not work there (pytorch/functorch#801), so ``hnn.interface.gradient_of``
    and the models' own second derivatives take ``torch.func``'s, and a check that reads a tensor's
    value in Python (a singular d2L/dqdot2, a state off its constraints, a blown-up rollout row) is
    skipped: vmap cannot branch on a value, and the trainer drops a model whose loss is not finite."""
    outer = _frozen.model_axis
    _frozen.model_axis = True
    try:
        yield
    finally:
        _frozen.model_axis = outer


def in_model_axis() -> bool:
    """Whether the caller runs inside ``model_axis`` (under vmap over models)."""
    return _frozen.model_axis


__all__ = ["frozen_kernels", "frozen_weights", "in_model_axis", "model_axis"]
