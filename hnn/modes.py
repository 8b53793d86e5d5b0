"""Modes that a caller sets and a lower layer reads, without either importing the other: today one,
``frozen_weights`` (a rollout promises that no weight changes, so a model may evaluate its field
through kernels built once per rollout).

    with torch.no_grad(), hnn.modes.frozen_weights():     # as hnn.rollout does
        dxdt = model.time_derivative(x)                    # the model may use a cached kernel
"""
from __future__ import annotations

import contextlib
import threading

_frozen = threading.local()     # .kernels: {(id(owner), key): (owner, kernel)} inside frozen_weights


@contextlib.contextmanager
def frozen_weights():
    """Within this context the models' weights do not change, so their fields may run as kernels
    built once (``hnn.rollout`` runs a non-differentiable rollout in it). Nested contexts share the
    outer one's kernels; leaving the outermost drops them."""
    outer = getattr(_frozen, "kernels", None)
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
    return getattr(_frozen, "kernels", None)


__all__ = ["frozen_kernels", "frozen_weights"]
