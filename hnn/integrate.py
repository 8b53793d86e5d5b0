"""Batched integration of dx/dt = f(x): one front door, ``rollout``.

Every method integrates the whole batch together, evaluating ``f`` once per stage on a
``(batch, dim)`` tensor, and returns ``(batch, len(t_eval), dim)``.
"""
from __future__ import annotations

import warnings
from typing import Callable

import numpy as np
import torch
from scipy.integrate import solve_ivp

Field = Callable[[torch.Tensor], torch.Tensor]


class DivergenceError(FloatingPointError):
    """A rollout produced non-finite states. ``trajectories`` and ``times`` say which and when."""

    def __init__(self, message: str, trajectories=(), times=()):
        super().__init__(message)
        self.trajectories = list(trajectories)
        self.times = list(times)


def _as_t_eval(t_eval) -> np.ndarray:
    t = np.asarray(t_eval.detach().cpu() if torch.is_tensor(t_eval) else t_eval, dtype=np.float64)
    if t.ndim != 1 or len(t) < 2:
        raise ValueError(f"t_eval must be a 1-D grid of at least 2 times, got shape {t.shape}")
    if not np.all(np.isfinite(t)):
        raise ValueError("t_eval contains NaN or inf")
    steps = np.diff(t)
    if not (np.all(steps > 0) or np.all(steps < 0)):
        raise ValueError("t_eval must be strictly increasing (or strictly decreasing to integrate backwards)")
    return t


def _divergence(message: str, bad_rows, times) -> DivergenceError:
    rows = [int(i) for i in bad_rows]
    shown = ", ".join(f"#{i} at t={t:.4g}" for i, t in zip(rows[:10], times[:10]))
    more = f" (+{len(rows) - 10} more)" if len(rows) > 10 else ""
    return DivergenceError(
        f"{message}: {len(rows)} trajectories diverged: {shown}{more}. Reduce the step size or tolerance, "
        "or check that the initial states lie where the model was trained.", rows, list(times))


def _solve_ivp(f: Field, x0: torch.Tensor, t: np.ndarray, rtol: float = 1e-3, atol: float = 1e-6,
               scipy_method: str = "RK45", max_norm: float | None = 1e6, stats: dict | None = None) -> torch.Tensor:
    """scipy's adaptive solver on the flattened batch: one call, one batched ``f`` per stage."""
    batch, dim = x0.shape
    dtype, device = x0.dtype, x0.device
    nfev = 0

    def fun(time, y):
        nonlocal nfev
        nfev += 1
        if max_norm is not None and not np.abs(y).max() <= max_norm:
            rows = np.nonzero(~(np.abs(y.reshape(batch, dim)) <= max_norm).all(axis=1))[0].tolist()
            raise _divergence(f"solve_ivp: states beyond max_norm={max_norm:g}", rows, [float(time)] * len(rows))
        x = torch.from_numpy(y.reshape(batch, dim))
        if x.dtype != dtype or x.device != device:
            x = x.to(dtype=dtype, device=device)
        dxdt = f(x).detach()
        if dxdt.shape != x.shape:
            raise ValueError(f"f must map (batch, dim) = {tuple(x.shape)} to the same shape, got {tuple(dxdt.shape)}")
        out = dxdt.cpu().numpy().reshape(-1)
        if not np.isfinite(out).all():
            rows = np.nonzero(~np.isfinite(out.reshape(batch, dim)).all(axis=1))[0].tolist()
            raise _divergence("solve_ivp: non-finite dx/dt", rows, [float(time)] * len(rows))
        return out

    y0 = x0.detach().cpu().numpy().astype(np.float64).reshape(-1)
    with torch.no_grad():
        sol = solve_ivp(fun, (t[0], t[-1]), y0, method=scipy_method, t_eval=t, rtol=rtol, atol=atol)
    if stats is not None:
        stats["nfev"] = nfev
    if not sol.success:
        raise DivergenceError(f"solve_ivp ({scipy_method}, rtol={rtol}, atol={atol}) failed at "
                              f"t={sol.t[-1] if len(sol.t) else t[0]:.4g}: {sol.message}")
    y = sol.y.reshape(batch, dim, len(t)).transpose(0, 2, 1)
    return torch.from_numpy(np.ascontiguousarray(y)).to(dtype=dtype, device=device)


def rk4_step(f: Field, x: torch.Tensor, dt) -> torch.Tensor:
    """The classic RK4 increment ``x(t + dt) - x(t)`` of dx/dt = f(x); ``dt`` a float or ``(batch, 1)``."""
    k1 = f(x)
    k2 = f(x + dt / 2 * k1)
    k3 = f(x + dt / 2 * k2)
    k4 = f(x + dt * k3)
    return dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)


# Dormand-Prince 5(4): the tableau of scipy's RK45, with a step size per trajectory
_DP_A = (
    (),
    (1 / 5,),
    (3 / 40, 9 / 40),
    (44 / 45, -56 / 15, 32 / 9),
    (19372 / 6561, -25360 / 2187, 64448 / 6561, -212 / 729),
    (9017 / 3168, -355 / 33, 46732 / 5247, 49 / 176, -5103 / 18656),
    (35 / 384, 0.0, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84),   # = the 5th-order solution (FSAL)
)
_DP_E = (-71 / 57600, 0.0, 71 / 16695, -71 / 1920, 17253 / 339200, -22 / 525, 1 / 40)
# its 4th-order continuous extension (Dormand & Prince; the coefficients scipy's RK45 uses):
# y(t + s h) = y + h * sum_j k_j * sum_m P[j][m] s^(m+1)
_DP_P = (
    (1.0, -8048581381 / 2820520608, 8663915743 / 2820520608, -12715105075 / 11282082432),
    (0.0, 0.0, 0.0, 0.0),
    (0.0, 131558114200 / 32700410799, -68118460800 / 10900136933, 87487479700 / 32700410799),
    (0.0, -1754552775 / 470086768, 14199869525 / 1410260304, -10690763975 / 1880347072),
    (0.0, 127303824393 / 49829197408, -318862633887 / 49829197408, 701980252875 / 199316789632),
    (0.0, -282668133 / 205662961, 2019193451 / 616988883, -1453857185 / 822651844),
    (0.0, 40617522 / 29380423, -110615467 / 29380423, 69997945 / 29380423),
)


def _dopri5(f: Field, x0: torch.Tensor, t: np.ndarray, rtol: float = 1e-3, atol: float = 1e-6,
            max_norm: float | None = 1e6, max_iterations: int = 1_000_000, stats: dict | None = None) -> torch.Tensor:
    """RK45 (Dormand-Prince) in torch with one adaptive step size per trajectory.

    Each row is controlled by its own error norm, exactly the norm of one scipy ``solve_ivp``
    call on that row, so one hard trajectory no longer sets the step of the whole batch (as it
    does in ``'solve_ivp'``, whose norm is the RMS over the batch). Outputs at ``t_eval`` come
    from the method's 4th-order dense output, as in scipy. All rows advance in lockstep
    iterations; once a quarter of them have finished, the finished ones are dropped, so ``f``
    sees only rows still running: it must treat rows independently (true of dynamics and of
    models), and a ``f`` that keeps per-trajectory state must carry each row's identity in the
    state itself.
    """
    batch, dim = x0.shape
    num_t = len(t)
    direction = 1.0 if t[-1] > t[0] else -1.0
    times = torch.as_tensor(t, dtype=torch.float64)
    y = x0.detach().clone()
    k1 = f(y).detach()
    nfev = 1
    tc = torch.full((batch,), float(t[0]), dtype=torch.float64)
    # scipy's initial step guess (Hairer, Norsett & Wanner), per row
    scale0 = atol + rtol * y.abs()
    d0 = (y / scale0).pow(2).mean(1).sqrt()
    d1 = (k1 / scale0).pow(2).mean(1).sqrt()
    h0 = torch.where((d0 < 1e-5) | (d1 < 1e-5), torch.full_like(d0, 1e-6), 0.01 * d0 / d1).to(torch.float64)
    y1 = y + direction * h0.to(y.dtype)[:, None] * k1
    d2 = ((f(y1).detach() - k1) / scale0).pow(2).mean(1).sqrt().to(torch.float64) / h0
    nfev += 1
    h1 = torch.where((d1 <= 1e-15) & (d2 <= 1e-15), torch.clamp(h0 * 1e-3, min=1e-6),
                     (0.01 / torch.maximum(d1.to(torch.float64), d2)) ** (1 / 5))
    prop = torch.minimum(100 * h0, h1)                   # proposed |step| per row
    out = torch.empty((batch, num_t, dim), dtype=x0.dtype)
    out[:, 0] = y
    nxt = torch.ones(batch, dtype=torch.long)
    done = torch.zeros(batch, dtype=torch.bool)
    bad_time = torch.full((batch,), float("nan"), dtype=torch.float64)
    rows = torch.arange(batch)
    eps = float(torch.finfo(torch.float64).eps)
    A = torch.zeros(7, 7, dtype=x0.dtype)
    for i, a in enumerate(_DP_A):
        A[i, :len(a)] = torch.tensor(a, dtype=x0.dtype)
    E = torch.tensor(_DP_E, dtype=x0.dtype)
    K = torch.empty((7, batch, dim), dtype=x0.dtype)       # the stage derivatives
    P = torch.tensor(_DP_P, dtype=x0.dtype)
    t_end = torch.tensor(float(t[-1]), dtype=torch.float64)
    for _ in range(max_iterations):
        live = int((~done).sum())
        if live == 0:
            break
        if live < 0.75 * len(y):        # drop finished rows: f then costs only what still runs
            keep = ~done
            y, k1, tc, prop, nxt, rows, done = y[keep], k1[keep], tc[keep], prop[keep], nxt[keep], rows[keep], done[keep]
            K = torch.empty((7, live, dim), dtype=x0.dtype)
        gap = (t_end - tc).abs()
        clipped = prop >= gap                         # this step ends on the last time
        h = torch.where(done, torch.zeros_like(prop), torch.minimum(prop, gap)) * direction
        hx = h.to(y.dtype)[:, None]
        K[0] = k1
        for s in range(1, 7):       # stage s: y + h * sum_j a_sj k_j, as one small matrix product
            stage = torch.addcmul(y, hx, (A[s, :s] @ K[:s].reshape(s, -1)).reshape(-1, dim))
            K[s] = f(stage).detach()
        nfev += 6
        y_new = stage
        err = hx * (E @ K.reshape(7, -1)).reshape(-1, dim)
        scale = atol + rtol * torch.maximum(y.abs(), y_new.abs())
        err_norm = (err / scale).pow(2).mean(1).sqrt().to(torch.float64)
        finite = torch.isfinite(y_new).all(1) & torch.isfinite(K[6]).all(1) & torch.isfinite(err_norm)
        if max_norm is not None:
            finite &= (y_new.abs() <= max_norm).all(1)
        blown = ~finite & ~done
        too_small = ~done & finite & (err_norm > 1) & (h.abs() <= 10 * eps * tc.abs().clamp(min=1.0))
        for mask in (blown, too_small):
            if mask.any():
                bad_time[rows[mask]] = tc[mask]
                done |= mask
        accept = ~done & (err_norm <= 1)
        acc = accept[:, None]
        t_new = torch.where(clipped, t_end, tc + h)
        if accept.any():
            # every output time inside (tc, t_new] of an accepted row, from the dense output
            Q = torch.einsum("sbd,sm->bdm", K, P)            # (batch, dim, 4)
            while True:
                tn = times[nxt.clamp(max=num_t - 1)]
                due = accept & ~done & (direction * (tn - t_new) <= 1e-12 * t_end.abs().clamp(min=1.0))
                if not due.any():
                    break
                i = torch.nonzero(due).flatten()
                sigma = ((tn[i] - tc[i]) / h[i]).to(y.dtype)
                powers = torch.stack([sigma, sigma ** 2, sigma ** 3, sigma ** 4], dim=1)   # (n, 4)
                out[rows[i], nxt[i]] = y[i] + hx[i] * (Q[i] @ powers[:, :, None])[..., 0]
                nxt[i] += 1
                done |= nxt >= num_t
        y = torch.where(acc, y_new, y)
        k1 = torch.where(acc, K[6], k1)
        tc = torch.where(accept, t_new, tc)
        # scipy's step-size rule: safety 0.9, factors in [0.2, 10], no growth right after a rejection
        factor = torch.where(err_norm == 0, torch.full_like(err_norm, 10.0),
                             (0.9 * err_norm.clamp(min=1e-300) ** -0.2).clamp(0.2, 10.0))
        factor = torch.where(accept, factor, factor.clamp(max=1.0))
        prop = h.abs() * factor
    else:
        raise DivergenceError(f"dopri5 did not finish in {max_iterations} iterations")
    if stats is not None:
        stats["nfev"] = nfev
    diverged = torch.nonzero(~torch.isnan(bad_time)).flatten().tolist()
    if diverged:
        raise _divergence(f"dopri5 (rtol={rtol}, atol={atol}, max_norm={max_norm})", diverged,
                          bad_time[diverged].tolist())
    return out


from .fixed_step import SYMPLECTIC_METHODS, fixed_step_rollout  # noqa: E402  (it uses DivergenceError above)

_METHODS = {"solve_ivp": _solve_ivp, "dopri5": _dopri5,
            **{m: (lambda f, x0, t, _m=m, **kw: fixed_step_rollout(f, x0, t, _m, **kw))
               for m in ("rk4",) + SYMPLECTIC_METHODS}}


def _check_tolerance(method: str, dtype: torch.dtype, options: dict) -> None:
    """Warn when an adaptive method is asked for a relative accuracy ``dtype`` cannot deliver."""
    rtol = options.get("rtol")
    eps = torch.finfo(dtype).eps
    if method in ("solve_ivp", "dopri5") and rtol is not None and rtol < 100 * eps:
        # f is evaluated in dtype: its rounding (~eps relative) caps the accuracy of every stage
        warnings.warn(f"{method}: rtol={rtol:g} is tighter than {dtype} can honour (100 * eps = {100 * eps:.3g}); "
                      f"the error will stall near eps: use rtol >= {100 * eps:.3g} or float64 states", stacklevel=3)


def rollout(f: Field, x0, t_eval, method: str = "solve_ivp", **options) -> torch.Tensor:
    """Integrate ``dx/dt = f(x)`` from every state of ``x0`` and sample at ``t_eval``.

    Args:
        f: maps a ``(batch, dim)`` tensor to ``dx/dt`` of the same shape (a model's
            ``time_derivative`` or a task's true dynamics).
        x0: initial states, ``(batch, dim)`` (a single state ``(dim,)`` is treated as batch 1).
            Its dtype is the dtype ``f`` is evaluated in.
        t_eval: 1-D times (units of the system), starting at the time of ``x0``.
        method: ``'solve_ivp'`` (scipy, adaptive; options ``rtol``, ``atol``,
            ``scipy_method='RK45'|'DOP853'|...``), ``'dopri5'`` (the same RK45 in torch with one
            step size per trajectory, each controlled as in its own scipy call; options ``rtol``,
            ``atol``), ``'rk4'`` (fixed step in torch; option ``dt``, default one step per
            ``t_eval`` interval), or the symplectic fixed-step methods of ``hnn.symplectic``
            (option ``dt`` as for rk4): ``'leapfrog'`` (Stormer-Verlet; exact only for
            separable H = T(p) + V(q), e.g. true dynamics), ``'midpoint'`` (implicit midpoint,
            for any H, the choice for learned models; options ``tol`` (default 1e-12 in float64,
            8 eps in float32) and ``max_iter`` (100) of its fixed-point iteration) and
            ``'yoshida4'`` (order 4; option ``base='leapfrog'|'midpoint'``). All accept
            ``stats={}``, filled with ``nfev``, the number of batched evaluations of ``f`` (and
            for the midpoint ``iterations`` and ``max_step_iterations``), and ``max_norm`` (default
            1e6; None to disable): a state with a component beyond it counts as blown up.
            Fixed-step methods take ``t_eval`` in either direction (backwards for reversibility).

    Returns:
        ``(batch, len(t_eval), dim)``, with ``x0`` at index 0.

    Raises:
        DivergenceError: when states or derivatives become non-finite or states exceed
            ``max_norm``, naming the trajectories and times (never a silent NaN);
            ``hnn.ConvergenceError`` (a subclass) when the midpoint iteration does not converge.

    Warns (``UserWarning``) when ``rtol`` (solve_ivp, dopri5) is below 100 eps of ``x0``'s dtype
    or the midpoint ``tol`` below its eps: tolerances the dtype cannot honour.
    """
    if method not in _METHODS:
        raise ValueError(f"unknown method {method!r}; choose one of {sorted(_METHODS)}")
    x0 = torch.as_tensor(x0)
    if x0.dim() == 1:
        x0 = x0[None]
    if x0.dim() != 2:
        raise ValueError(f"x0 must have shape (batch, dim), got {tuple(x0.shape)}")
    if not x0.is_floating_point():
        x0 = x0.to(torch.get_default_dtype())
    if not torch.isfinite(x0).all():
        rows = torch.nonzero(~torch.isfinite(x0).all(dim=1)).flatten().tolist()
        raise ValueError(f"x0 has non-finite values in rows {rows[:10]}")
    _check_tolerance(method, x0.dtype, options)
    return _METHODS[method](f, x0, _as_t_eval(t_eval), **options)
