"""The adaptive integrators behind ``hnn.rollout``: scipy's ``solve_ivp`` on the flattened batch,
and Dormand-Prince 5(4) in torch with one step size per trajectory (``'dopri5'``).

Both take a checked ``(batch, dim)`` ``x0`` and a float64 grid ``t`` from ``rollout`` and return
``(batch, len(t), dim)``; ``hnn.solvers`` registers them as ``'solve_ivp'`` and ``'dopri5'``.
"""
from __future__ import annotations

import numpy as np
import torch
from scipy.integrate import solve_ivp

from .errors import DivergenceError, divergence_error
from .fixed_step import Field

DEFAULT_SCIPY_METHOD = "RK45"    # solve_ivp's own default; reports name the integrator by it


def scipy_rollout(f: Field, x0: torch.Tensor, t: np.ndarray, rtol: float = 1e-3, atol: float = 1e-6,
                  scipy_method: str = DEFAULT_SCIPY_METHOD, max_norm: float | None = 1e6,
                  stats: dict | None = None) -> torch.Tensor:
    """scipy's adaptive solver on the flattened batch: one call, one batched ``f`` per stage."""
    batch, dim = x0.shape
    dtype, device = x0.dtype, x0.device
    nfev = 0

    def fun(time, y):
        nonlocal nfev
        nfev += 1
        if max_norm is not None and not np.abs(y).max() <= max_norm:
            rows = np.nonzero(~(np.abs(y.reshape(batch, dim)) <= max_norm).all(axis=1))[0].tolist()
            raise divergence_error(f"solve_ivp: states beyond max_norm={max_norm:g}", rows,
                                   [float(time)] * len(rows))
        x = torch.from_numpy(y.reshape(batch, dim))
        if x.dtype != dtype or x.device != device:
            x = x.to(dtype=dtype, device=device)
        dxdt = f(x).detach()
        if dxdt.shape != x.shape:
            raise ValueError(f"f must map (batch, dim) = {tuple(x.shape)} to the same shape, got {tuple(dxdt.shape)}")
        out = dxdt.cpu().numpy().reshape(-1)
        if not np.isfinite(out).all():
            rows = np.nonzero(~np.isfinite(out.reshape(batch, dim)).all(axis=1))[0].tolist()
            raise divergence_error("solve_ivp: non-finite dx/dt", rows, [float(time)] * len(rows))
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


def dopri5_rollout(f: Field, x0: torch.Tensor, t: np.ndarray, rtol: float = 1e-3, atol: float = 1e-6,
                   max_norm: float | None = 1e6, max_iterations: int = 1_000_000,
                   stats: dict | None = None) -> torch.Tensor:
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
        raise divergence_error(f"dopri5 (rtol={rtol}, atol={atol}, max_norm={max_norm})", diverged,
                               bad_time[diverged].tolist())
    return out

