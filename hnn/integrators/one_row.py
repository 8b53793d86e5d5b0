"""The per-row adaptive driver (``hnn.integrators.adaptive.per_row_rollout``) on one trajectory: the same
iteration with its bookkeeping (times, step sizes, output indices, the accept test and the step's bounds)
in Python floats instead of one-element arrays.

On one state each numpy call costs its dispatch, a microsecond or two, and the general driver makes some
forty a step besides the stages; here the scalars cost tens of nanoseconds. The formulas and their order
are the general driver's, so a row gets the same bits either way (tests/test_integrate.py holds a row alone
to the same row in a batch): the stage products, the error norm, the dense output and the powers of the
step rule still run on the arrays, as there (numpy's power on an array can round differently from
Python's ``**`` on a float).
"""
from __future__ import annotations

import numpy as np

from .dop853 import Stages, ToleranceScale
from ..errors import DivergenceError

_largest = np.maximum.reduce       # a.max() as its ufunc computes it (NaN wins), without the method's wrapper
_EPS = float(np.finfo(np.float64).eps)


def one_row(scheme, field, y: np.ndarray, k1: np.ndarray, t: np.ndarray, prop: float, out: np.ndarray,
            rtol: float, atol: float, max_norm: float | None, max_iterations: int, name: str) -> tuple[int, int, float | None]:
    """Steps the one row ``y`` ``(1, dim)`` (``k1`` = f(y), ``prop`` its first |step|) over ``t`` with the
    built ``scheme``, writing its states at ``t[1:]`` into ``out`` ``(len(t), dim)`` (``out[0]`` is the start's).
    Returns ``(field calls, rejected steps, the time it blew up or stalled at or None)``; a
    ``DivergenceError`` naming the solver ``name`` past ``max_iterations``."""
    dim = y.shape[1]
    dtype = y.dtype
    num_t = len(t)
    direction = 1.0 if t[-1] > t[0] else -1.0
    t_end = float(t[-1])
    near = 1e-12 * max(abs(t_end), 1.0)
    bound = max_norm if max_norm is not None else float(np.finfo(np.float64).max)
    exponent = 1.0 / scheme.order
    power = -(exponent - 0.75 * scheme.beta)
    err_old = np.full(1, 1e-4)
    tc = float(t[0])
    nxt = 1
    t_next = float(t[min(1, num_t - 1)])
    work = Stages.empty(scheme.stages, 1, dim, dtype)
    K = work.K
    nfev = rejected = 0
    held = False        # a step was just rejected: under scipy's clause (``hold_after_reject``) the next may not grow
    scale_tol = ToleranceScale(rtol, atol)

    for _ in range(max_iterations):
        if nxt >= num_t:
            return nfev, rejected, None
        gap = abs(t_end - tc)
        clipped = prop >= gap
        size = min(prop, gap)
        h = -size if direction < 0 else size
        hx = np.full((1, dim), h, dtype=dtype)
        K[0] = k1
        y_new, err_norm, calls = scheme.attempt(field, y, hx, work, scale_tol)
        nfev += calls
        err = float(err_norm[0])
        largest = float(_largest(scale_tol.abs_new, None))
        accept = largest <= bound and err <= 1.0
        if not accept:
            finite = (largest <= max_norm if max_norm is not None else np.isfinite(largest)) and np.isfinite(err)
            if not finite or (err > 1 and abs(h) <= 10 * _EPS * max(abs(tc), 1.0)):
                return nfev, rejected, tc
            rejected += 1
            held = scheme.hold_after_reject
        else:
            t_new = t_end if clipped else tc + h
            if (t_next - t_new) * direction <= near:
                evaluate, calls = scheme.dense(field, y, y_new, hx, work)
                nfev += calls
                last = nxt
                while last < num_t and direction * (float(t[last]) - t_new) <= near:
                    last += 1
                if last > nxt:
                    sigma = ((t[nxt:last] - tc) / h).astype(dtype, copy=False)
                    out[nxt:last] = evaluate(sigma, np.zeros(last - nxt, dtype=np.int64))
                nxt = last
                t_next = float(t[min(nxt, num_t - 1)])
            y, k1, tc = y_new, K[scheme.fsal].copy(), t_new
        factor = np.maximum(err_norm, 1e-300) ** power
        factor *= scheme.safety
        if scheme.beta:
            factor *= err_old ** scheme.beta
            if accept:
                err_old = np.maximum(err_norm, 1e-4)
        factor = min(max(float(factor[0]), scheme.min_factor), scheme.max_factor)
        if held and accept:
            factor, held = min(factor, 1.0), False
        prop = size * factor
    raise DivergenceError(f"{name} did not finish in {max_iterations} iterations")
