"""The balanced loss: each component of dx/dt weighed by its size in the training targets, so the
user's units do not decide what a fit of dx/dt learns (``--balance``, issue 48).

The paper's L2 loss sums squared errors of every component of dx/dt alike. Where one component is
far larger than another (dp/dt of heavy bodies, in N m, against dq/dt in rad/s) the small ones
barely enter it: on the two-link arm at 10 kg links the mechanical kind's M^-1, which only dq/dt =
M^-1 p reads directly, came out 31% wrong while the loss was low (docs/arm.md). Dividing each
component's error by its RMS over the training targets makes the loss the same whatever unit each
component is measured in.

    weights = balance_weights(dxdt, "auto", "l2")     # None (the plain loss) or (dim,) per-component weights
    hnn.train(model, x, dxdt, loss_weights=weights)

``weights[j] = 1 / rms_j^k`` (k = 2 for ``l2``, 1 for ``l1``): each component's error in units of
its own size, so the loss is a pure number. A change of the units of any component (of q, p or t)
scales that component's targets and errors alike and leaves the loss, its gradient and so the
whole training exactly as they were, weight decay and Adam's epsilon included, wherever the
network reads the same inputs (``tests/test_balance.py`` trains through a 10^3 change). ``'auto'``
balances only where the largest component's RMS exceeds the smallest's by more than
``AUTO_RATIO``; at or below it the plain loss, so every task whose components are of one size (the
paper's six) trains and names its runs as before.
"""
from __future__ import annotations

import numpy as np
import torch

from .names import BALANCES

# 'auto' balances above this ratio of the largest to the smallest component RMS of dx/dt. On the
# two-link arm with the plain loss the mechanical kind's M^-1 error was 3% at a ratio of 6.4 (1 kg
# links), 11% at 19 (3 kg) and 31% at 64 (10 kg) (docs/arm.md); the paper's tasks' targets lie at
# ratios 1.0 (spring, real) to 3.6 (3-body), the measured scenes' at 1.0 to 2.5.
AUTO_RATIO = 10.0


def component_rms(dxdt) -> np.ndarray:
    """The RMS of each column of ``dxdt`` ``(rows, dim)``, float64 ``(dim,)``."""
    y = np.asarray(dxdt.detach().cpu() if torch.is_tensor(dxdt) else dxdt, dtype=np.float64)
    if y.ndim != 2 or not len(y):
        raise ValueError(f"dxdt must have shape (rows, dim) with rows > 0, got {y.shape}")
    return np.sqrt((y ** 2).mean(axis=0))


def scale_ratio(dxdt) -> float:
    """Largest over smallest component RMS of ``dxdt`` (inf where a component is all zero)."""
    rms = component_rms(dxdt)
    return float(rms.max() / rms.min()) if rms.min() > 0 else float("inf")


def balance_weights(dxdt, balance: str = "auto", derivative_loss: str = "l2") -> np.ndarray | None:
    """The per-component weights ``(dim,)`` of the loss of a fit to targets ``dxdt`` ``(rows, dim)``,
    or None for the plain loss (``balance='off'``, or ``'auto'`` at a ratio <= ``AUTO_RATIO``).
    A component that is zero in every target is refused (ValueError): it has no size to weigh by."""
    if balance not in BALANCES:
        raise ValueError(f"balance={balance!r}: choose one of {', '.join(BALANCES)}")
    if derivative_loss not in ("l2", "l1"):
        raise ValueError(f"derivative_loss={derivative_loss!r}: choose l2 or l1")
    if balance == "off" or (balance == "auto" and scale_ratio(dxdt) <= AUTO_RATIO):
        return None
    size = component_rms(dxdt) ** (2 if derivative_loss == "l2" else 1)
    if not np.isfinite(size).all():
        wide = np.nonzero(~np.isfinite(size))[0].tolist()
        raise ValueError(f"balance={balance!r}: the sizes of components {wide} of dx/dt overflow (their RMS, "
                         f"{'squared ' if derivative_loss == 'l2' else ''}is not finite): the targets hold values too "
                         "large for float64 arithmetic; find and fix them, or rescale the data")
    if not (size > 0).all():
        zero = np.nonzero(size == 0)[0].tolist()
        raise ValueError(f"balance={balance!r}: components {zero} of dx/dt are 0 in every training target, so they "
                         "have no size to weigh by; drop those coordinates or use balance='off'")
    return 1.0 / size


def weighted(loss, weights):
    """``loss`` ``(x, y) -> (rows, dim)`` with each column times ``weights`` ``(dim,)`` (made a tensor
    once: give it in the loss's dtype and device, and a step moves nothing)."""
    weights = torch.as_tensor(weights)

    def balanced(xb, yb):
        per_element = loss(xb, yb)
        return per_element * weights.to(per_element)
    return balanced
