"""The adaptive integrators behind ``hnn.rollout``: scipy's ``solve_ivp`` on the flattened batch,
and Dormand-Prince 5(4) and 8(5,3) with one step size per trajectory (``'dopri5'``, ``'dop853'``,
stepped in numpy).

All take a checked ``(batch, dim)`` ``x0`` and a float64 grid ``t`` from ``rollout`` and return
``(batch, len(t), dim)``; ``hnn.integrators.solvers`` registers them as ``'solve_ivp'``, ``'dopri5'`` and ``'dop853'``.
"""
from __future__ import annotations

import functools

import numpy as np
import torch
from scipy.integrate import solve_ivp

from .dop853 import DOP853, ScipyDOP853, Stages, ToleranceScale, rk_stages, tableau_rows
from ..errors import DivergenceError, divergence_error
from .fixed_step import Field
from .one_row import one_row

DEFAULT_SCIPY_METHOD = "RK45"    # solve_ivp's own default; reports name the integrator by it

# The adaptive methods' tolerances where a caller gives none, on float64 states. Measured (docs/integrators.md,
# "Default tolerances"): over ten training lengths the true pendulum keeps its energy to 1e-6 relative at
# these (1.2e-6 RK45, 3.1e-6 dopri5, 6.4e-7 dop853), the spring to 2e-6, the 2-body orbits to 1.1e-5 and
# the chaotic 3-body to 1.2e-4, all far under the learned models' energy errors (1e-2 and up); scipy's own
# defaults (rtol 1e-3, atol 1e-6) let the pendulum's energy drift 11% (RK45), 3.7% (dopri5), 1.1% (dop853).
RTOL, ATOL = 1e-7, 1e-9


def default_tolerances(dtype: torch.dtype) -> tuple[float, float]:
    """``(rtol, atol)`` of an adaptive rollout in ``dtype`` when the caller gives none: ``RTOL``, ``ATOL`` in
    float64; in a coarser dtype 100 eps (float32: 1.2e-5) and a hundredth of it, the tightest its rounding
    honours. Tighter, a float32 field's rounding noise drives the step down: dop853 on a float32 spring HNN
    took 2.3e3 field calls at rtol 1e-6, 5.6e4 at 1e-7 and 5.1e5 at 1e-8."""
    rtol = max(RTOL, 100 * torch.finfo(dtype).eps)
    return rtol, rtol * (ATOL / RTOL)


def scipy_rollout(f: Field, x0: torch.Tensor, t: np.ndarray, rtol: float = RTOL, atol: float = ATOL,
                  scipy_method: str = DEFAULT_SCIPY_METHOD, max_norm: float | None = 1e6,
                  stats: dict | None = None, max_calls: int | None = None) -> torch.Tensor:
    """scipy's adaptive solver on the flattened batch: one call, one batched ``f`` per stage. ``max_calls``:
    a ``DivergenceError`` past that many calls of ``f`` (a field stiff along the path shrinks the step
    without end: scipy has no bound of its own); None: no bound."""
    batch, dim = x0.shape
    dtype, device = x0.dtype, x0.device
    nfev = 0

    def fun(time, y):
        nonlocal nfev
        nfev += 1
        if max_calls is not None and nfev > max_calls:
            raise DivergenceError(f"solve_ivp ({scipy_method}, rtol={rtol}): over {max_calls} calls of the field by "
                                  f"t={float(time):.4g} of [{t[0]:g}, {t[-1]:g}]: it is stiff along this path, so the "
                                  "step fell without end; loosen rtol, or check that the starts lie where the "
                                  "model was trained")
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


class _Dopri5:
    """The Dormand-Prince 5(4) scheme of ``per_row_rollout`` (scipy's RK45 step-size rule:
    error exponent 1/5, a step grows at most 10x and shrinks at most 5x, no PI term: ``beta`` =
    0.04 cost about as much more as it gained in error here)."""

    order = 5
    stages = 7
    fsal = 6
    dense_stages = 0        # the dense output reads the step's own stages: no further calls of f
    safety, min_factor, max_factor, beta = 0.9, 0.2, 10.0, 0.0
    hold_after_reject = False   # scipy's clause, left out here: docs/speed.md, "Tried and not kept"

    def __init__(self, dtype: torch.dtype):
        cpu = dict(dtype=dtype, device="cpu")        # the stepping runs in numpy, on any device's states
        A = torch.zeros((7, 7), **cpu)
        for i, a in enumerate(_DP_A):
            A[i, :len(a)] = torch.tensor(a, **cpu)
        self.A_rows = tableau_rows([A[s, :s] for s in range(7)])
        self.E = torch.tensor(_DP_E, **cpu)[None]
        self.PT = torch.tensor(_DP_P, **cpu).T.contiguous()   # (4, 7)

    def attempt(self, field, y, hx, work: Stages, scale_tol):
        stage = rk_stages(field, self.A_rows, range(1, 7), y, hx, work)     # the last: the new state (FSAL)
        err = work.combine(self.E, 7) * hx
        err /= scale_tol(y, stage)
        err *= err
        # the mean as numpy's mean computes it (the same bits), without its Python wrapper
        return stage, np.sqrt(np.add.reduce(err, 1) / err.shape[1]).astype(np.float64, copy=False), 6

    def dense(self, field, y, y_new, hx, work: Stages):
        # Q as (4, dim, rows): a row's powers of sigma then scale a contiguous run (the (rows, dim) layout
        # broadcast them over runs of dim, several times slower on a few states; the same products)
        Q = torch.mm(self.PT, work.flat).numpy().reshape(4, *y.shape).transpose(0, 2, 1)

        one = len(y) == 1       # one row (one state, or a shared step's batch): j is all its own, and broadcasting
        #                         its arrays over the outputs gives the same products as gathering them

        def evaluate(sigma, j):
            # (4, dim, n); take, not q[..., j]: the same rows without the indexing's overhead
            q = Q if one else Q.take(j, 2)
            # sum_m sigma^(m+1) Q[m] in the order numpy's sum over the powers took (np.stack's, several times the sum)
            value = sigma * q[0]
            value += sigma ** 2 * q[1]
            value += sigma ** 3 * q[2]
            value += sigma ** 4 * q[3]
            value = value.T
            value *= hx if one else hx.take(j, 0)
            value += y if one else y.take(j, 0)
            return value
        return evaluate, 0


class _ScipyDopri5(_Dopri5):
    """RK45 on scipy's terms, the scheme of ``steps='shared'``: with scipy's clause that no step grows right
    after a rejection, so a batch stepped as one system makes scipy's calls on the flattened batch (the
    one-step-per-row scheme leaves the clause out: it moves every path that rejects a step, the datasets')."""
    hold_after_reject = True


def _numpy_field(f: Field, dtype: torch.dtype, device: torch.device):
    """``f`` on numpy states ``(rows, dim)``: the tensors share the arrays' memory on the CPU. A field that
    takes numpy states itself (the ``numpy`` of an ``hnn.interface.EnergyField``) is called so where it serves them."""
    on_cpu = device.type == "cpu"
    direct = getattr(f, "numpy", None) if on_cpu else None

    def field(y: np.ndarray) -> np.ndarray:
        if direct is not None:
            dxdt = direct(y)
            if dxdt is not None:
                return dxdt
        x = torch.from_numpy(y)
        if not on_cpu:
            x = x.to(device)
        dxdt = f(x)
        if dxdt.shape != x.shape:
            raise ValueError(f"f must map (batch, dim) = {tuple(x.shape)} to the same shape, got {tuple(dxdt.shape)}")
        if dxdt.is_cpu and not dxdt.requires_grad:      # the common case: no detach and no copy to make
            return dxdt.numpy()
        return dxdt.detach().cpu().numpy()
    return field


def dopri5_rollout(f: Field, x0: torch.Tensor, t: np.ndarray, rtol: float = RTOL, atol: float = ATOL,
                   max_norm: float | None = 1e6, max_iterations: int = 1_000_000,
                   stats: dict | None = None, drop_finished: bool = True, steps: str = "row") -> torch.Tensor:
    """RK45 (Dormand-Prince) with one adaptive step size per trajectory.

    Each row is controlled by its own error norm, exactly the norm of one scipy ``solve_ivp``
    call on that row, so one hard trajectory no longer sets the step of the whole batch (as it
    does in ``'solve_ivp'``, whose norm is the RMS over the batch). The step rule is scipy's but for
    one clause: scipy lets no step grow right after a rejection, this one does (so a row with a
    rejected step can part from its scipy call; docs/speed.md, "Tried and not kept"). Outputs at ``t_eval`` come
    from the method's 4th-order dense output, as in scipy. All rows advance in lockstep
    iterations; once a quarter of them have finished, the finished ones are dropped, so ``f``
    sees only rows still running: it must treat rows independently (true of dynamics and of
    models). ``drop_finished=False`` passes every row to every call of ``f`` instead (a finished row
    is held with a zero step), for a ``f`` that ties a row to its position: a per-trajectory time
    scale, a group's stacked field (``hnn.integrators.groups.group_field``); each row's path is the same either
    way. The stepping runs in numpy on the states' dtype (on a few states an operation
    costs several times less there than in torch: docs/speed.md, "Why the fast paths"), ``f`` on tensors sharing the arrays' memory.

    ``steps='shared'`` steps the batch as one system instead, as ``'solve_ivp'`` does: one step size for
    every row, set by the RMS of the error over the whole batch (``SHARED_STEPS``), under scipy's whole rule,
    its clause too (``_ScipyDopri5``): the calls of scipy's RK45 on the flattened batch.
    """
    return per_row_rollout(_ScipyDopri5 if steps == "shared" else _Dopri5, "dopri5", f, x0, t, rtol, atol, max_norm,
                           max_iterations, stats, drop_finished, steps)


def dop853_rollout(f: Field, x0: torch.Tensor, t: np.ndarray, rtol: float = RTOL, atol: float = ATOL,
                   max_norm: float | None = 1e6, max_iterations: int = 1_000_000,
                   stats: dict | None = None, drop_finished: bool = True, steps: str = "row") -> torch.Tensor:
    """Dormand-Prince 8(5,3) (Hairer's DOP853, ``hnn.integrators.dop853``) with one step size per trajectory.

    As ``dopri5_rollout`` in all else (rows controlled alone, finished rows dropped unless
    ``drop_finished=False``, ``f`` must
    treat rows independently), with the method's 7th-order dense output at ``t_eval``: 12 field
    calls a step, 3 more on the rows that have an output time inside it. Order 8: at tight
    tolerances it takes several times fewer steps than dopri5 for the same error. ``steps='shared'``: one step
    size for the batch, as ``dopri5_rollout``'s, under scipy's DOP853 step rule (``ScipyDOP853``).
    """
    return per_row_rollout(ScipyDOP853 if steps == "shared" else DOP853, "dop853", f, x0, t, rtol, atol, max_norm,
                           max_iterations, stats, drop_finished, steps)


_largest = np.maximum.reduce       # a.max() as its ufunc computes it (NaN wins), without the method's wrapper


@functools.lru_cache(maxsize=None)
def _built(scheme, dtype: torch.dtype):
    """``scheme(dtype)``, built once: its tables are constants (building DOP853's took a large share of
    a short rollout on one state)."""
    return scheme(dtype)


# ``steps=`` of the per-row methods. 'row': one step size per row, each row's path its own (the default: a
# row's answer does not depend on the batch it came in). 'shared': the batch as one system of batch * dim
# components, one step size and one error norm (the RMS over every component), as scipy's solve_ivp and
# torchdiffeq step a batch. On a batch of alike trajectories the shared step is set by the RMS, under the
# hardest row's error: it makes about the calls scipy makes at a given tolerance, each on every row, with
# the one-row driver's bookkeeping (docs/integrators.md, "work-precision").
SHARED_STEPS = ("row", "shared")


def per_row_rollout(scheme, name: str, f: Field, x0: torch.Tensor, t: np.ndarray, rtol: float, atol: float,
                    max_norm: float | None, max_iterations: int, stats: dict | None,
                    drop_finished: bool = True, steps: str = "row") -> torch.Tensor:
    """An embedded Runge-Kutta ``scheme`` (a class like ``hnn.integrators.dop853.DOP853``, built for the dtype)
    with one step size per row (``steps='shared'``: one for the batch): the driver of ``dopri5_rollout`` and
    ``dop853_rollout``."""
    if steps not in SHARED_STEPS:
        raise ValueError(f"{name}: steps={steps!r} is not one of {SHARED_STEPS}: 'row' gives each trajectory its "
                         "own step size, 'shared' one for the whole batch (as solve_ivp)")
    built, field = _built(scheme, x0.dtype), _numpy_field(f, x0.dtype, x0.device)
    with np.errstate(all="ignore"):     # a blown-up row is reported by name below, not by numpy warnings
        if steps == "shared" and len(x0) > 1:
            return _shared(built, name, field, x0, t, rtol, atol, max_norm, max_iterations, stats)
        return _per_row(built, name, field, x0, t, rtol, atol, max_norm, max_iterations, stats, drop_finished)


def _shared(scheme, name, field, x0: torch.Tensor, t: np.ndarray, rtol, atol, max_norm, max_iterations,
            stats) -> torch.Tensor:
    """The batch ``x0`` ``(batch, dim)`` stepped as one row of ``batch * dim`` components (``SHARED_STEPS``);
    a blow-up stops every row, so a ``DivergenceError`` names them all."""
    batch, dim = x0.shape

    def flat_field(y: np.ndarray) -> np.ndarray:
        return field(y.reshape(batch, dim)).reshape(1, batch * dim)
    try:
        out = _per_row(scheme, name, flat_field, x0.reshape(1, batch * dim), t, rtol, atol, max_norm,
                       max_iterations, stats, True)
    except DivergenceError as err:
        if not err.times:
            raise
        raise divergence_error(f"{name} (steps='shared', rtol={rtol}, atol={atol}, max_norm={max_norm})",
                               range(batch), err.times * batch) from None
    return out.reshape(len(t), batch, dim).transpose(0, 1).contiguous()


def _per_row(scheme, name, field, x0: torch.Tensor, t: np.ndarray, rtol, atol, max_norm, max_iterations,
             stats, drop_finished) -> torch.Tensor:
    batch, dim = x0.shape
    num_t = len(t)
    direction = 1.0 if t[-1] > t[0] else -1.0
    y = x0.detach().cpu().numpy().copy()
    dtype = y.dtype
    k1 = field(y).astype(dtype, copy=True)
    nfev = 1
    rejected = 0                        # row-steps rejected by the error test
    err_old = np.full(batch, 1e-4)
    tc = np.full(batch, float(t[0]))
    exponent = 1.0 / scheme.order       # the error estimate is one order lower: err ~ h^order
    # scipy's initial step guess (Hairer, Norsett & Wanner), per row
    scale0 = atol + rtol * np.abs(y)
    d0 = np.sqrt(((y / scale0) ** 2).mean(1))
    d1 = np.sqrt(((k1 / scale0) ** 2).mean(1))
    h0 = np.where((d0 < 1e-5) | (d1 < 1e-5), 1e-6, 0.01 * d0 / d1).astype(np.float64)
    y1 = y + (direction * h0).astype(dtype)[:, None] * k1
    d2 = np.sqrt((((field(y1) - k1) / scale0) ** 2).mean(1)).astype(np.float64) / h0
    nfev += 1
    h1 = np.where((d1 <= 1e-15) & (d2 <= 1e-15), np.maximum(h0 * 1e-3, 1e-6),
                  (0.01 / np.maximum(d1.astype(np.float64), d2)) ** exponent)
    prop = np.minimum(100 * h0, h1)                      # proposed |step| per row
    out = np.empty((batch, num_t, dim), dtype=dtype)
    out[:, 0] = y
    if batch == 1:      # one trajectory: the same iteration with its bookkeeping in Python floats (same bits)
        calls, rejected, bad = one_row(scheme, field, y, k1, t, float(prop[0]), out[0], rtol, atol, max_norm,
                                       max_iterations, name)
        return _finish(name, out, x0.device, nfev + calls, rejected, np.array([np.nan if bad is None else bad]),
                       stats, rtol, atol, max_norm)
    nxt = np.ones(batch, dtype=np.int64)
    t_next = np.full(batch, t[min(1, num_t - 1)])          # t[nxt] (the last time once past it), kept as nxt moves
    done = np.zeros(batch, dtype=bool)
    bad_time = np.full(batch, np.nan)
    rows = np.arange(batch)
    eps = float(np.finfo(np.float64).eps)
    work = Stages.empty(scheme.stages, batch, dim, dtype)           # the stage derivatives, work.K
    t_end = float(t[-1])
    near = 1e-12 * max(abs(t_end), 1.0)
    forward = direction * t                                         # the output times, ascending
    # a state is blown up past this (max_norm None: past the largest finite value, i.e. inf; NaN fails both)
    bound = max_norm if max_norm is not None else float(np.finfo(np.float64).max)
    scale_tol = ToleranceScale(rtol, atol)  # keeps |y_new| of the last attempt for the blow-up test

    # Each iteration's own work is some forty numpy calls on arrays of a few elements, each costing its
    # dispatch, not its arithmetic: the common iteration (no row finished, none rejected or blown up)
    # takes a shorter way through the same formulas, so every path keeps its bits.
    finished = 0
    for _ in range(max_iterations):
        live = len(y) - finished
        if live == 0:
            break
        if drop_finished and live < 0.75 * len(y):        # drop finished rows: f then costs only what still runs
            keep = ~done
            y, k1, tc, prop, nxt, rows, done = y[keep], k1[keep], tc[keep], prop[keep], nxt[keep], rows[keep], done[keep]
            t_next = t_next[keep]
            err_old = err_old[keep]
            work = Stages.empty(scheme.stages, live, dim, dtype)
            finished = 0
        K = work.K
        gap = np.abs(t_end - tc)
        clipped = prop >= gap                         # this step ends on the last time
        size = np.minimum(prop, gap)                  # |h|
        if finished:
            size[done] = 0.0
        h = size * direction if direction < 0 else size
        # each row's step on each of its components, (rows, dim): a product with it then runs over contiguous
        # elements (a (rows, 1) column broadcast over a few components costs several times as much; the same bits)
        hx = h.astype(dtype, copy=False)[:, None].repeat(dim, 1)
        K[0] = k1
        # the tableau products in torch (work.combine): its small products give each row the same bits
        # whatever the other rows (numpy's BLAS does not), so a row's path does not depend on the batch
        y_new, err_norm, calls = scheme.attempt(field, y, hx, work, scale_tol)
        nfev += calls
        # a NaN or inf in y_new makes its row's max NaN or inf, one in a stage the error norm: every row
        # passes both tests when the largest of each does (NaN fails a comparison). The ufuncs' own reduce and
        # count_nonzero below, not the methods max and any: the same answers without their Python wrappers
        calm = not finished and float(_largest(scale_tol.abs_new, None)) <= bound and float(_largest(err_norm)) <= 1.0
        if not calm:
            largest = _largest(scale_tol.abs_new, 1)
            finite = (largest <= max_norm if max_norm is not None else np.isfinite(largest)) & np.isfinite(err_norm)
            over = err_norm > 1
        if not calm and (over.any() or not finite.all()):          # else no row blew up or stalled: skip the masks
            running = ~done
            blown = ~finite & running
            too_small = running & finite & over & (np.abs(h) <= 10 * eps * np.maximum(np.abs(tc), 1.0))
            for mask in (blown, too_small):
                if mask.any():
                    bad_time[rows[mask]] = tc[mask]
                    done |= mask
            finished = int(np.count_nonzero(done))
        accept = None if calm else ~done & (err_norm <= 1)          # None: every row
        t_new = np.where(clipped, t_end, tc + h)
        ahead = t_next - t_new
        if direction < 0:
            ahead *= direction
        due = ahead <= near if calm else accept & (ahead <= near)
        if np.count_nonzero(due):
            # every output time inside (tc, t_new] of an accepted row, from the dense output, all at once
            i = due.nonzero()[0]
            # a field that ties a row to its position (drop_finished=False) is given every row in every call,
            # the dense stages' too (dop853's): at, the due rows' places among the rows it was given
            # (a dense output that calls f for no further stages is read from every row's stages: no copy)
            if drop_finished and scheme.dense_stages and len(i) < len(y):
                at = np.arange(len(i))
                evaluate, calls = scheme.dense(field, y.take(i, 0), y_new.take(i, 0), hx.take(i, 0), Stages(K.take(i, 1)))
            else:
                at = i
                evaluate, calls = scheme.dense(field, y, y_new, hx, work)
            nfev += calls
            first = nxt.take(i)
            after = first + 1
            following = t.take(np.minimum(after, num_t - 1))      # each due row's next output time (or the last)
            beyond = following - t_new.take(i)
            if direction < 0:
                beyond *= direction
            if np.count_nonzero((beyond <= near) & (after < num_t)):
                # some row's step holds several output times: each due row's times from nxt on that pass
                # the test (monotone in the index); searchsorted on the times in the direction of travel
                # bounds them, with room for its rounding
                counts = np.minimum(forward.searchsorted(direction * t_new.take(i) + 2 * near, "right"), num_t) - first
                j = np.repeat(np.arange(len(i)), counts)                # a due row (index into i) per output
                k = np.arange(len(j)) + np.repeat(first - (np.cumsum(counts) - counts), counts)     # its output time
                inside = direction * (t[k] - t_new[i[j]]) <= near
                j, k = j[inside], k[inside]
                ij = i[j]
                sigma = ((t[k] - tc[ij]) / h[ij]).astype(dtype, copy=False)
                out[rows[ij], k] = evaluate(sigma, at[j])
                nxt[i] += np.bincount(j, minlength=len(i))
                t_next[i] = t[np.minimum(nxt[i], num_t - 1)]
            else:       # the common step: one output time in each due row's step, nxt's (the same as above)
                sigma = ((t.take(first) - tc.take(i)) / h.take(i)).astype(dtype, copy=False)
                out[rows.take(i), first] = evaluate(sigma, at)
                nxt[i] = after
                t_next[i] = following
            done |= nxt >= num_t
            finished = int(np.count_nonzero(done))
        if calm or accept.all():
            y, k1, tc = y_new, K[scheme.fsal].copy(), t_new
        else:
            y = np.where(accept[:, None], y_new, y)
            k1 = np.where(accept[:, None], K[scheme.fsal], k1)
            tc = np.where(accept, t_new, tc)
        # the step-size rule: a safety factor, the scheme's PI term (beta), bounded growth and
        # shrinking (a rejected row's factor is below one already: its error is above one)
        factor = np.maximum(err_norm, 1e-300) ** -(exponent - 0.75 * scheme.beta)
        factor *= scheme.safety
        if scheme.beta:
            factor *= err_old ** scheme.beta
            err_old = np.maximum(err_norm, 1e-4) if calm else np.where(accept, np.maximum(err_norm, 1e-4), err_old)
        factor = np.minimum(np.maximum(factor, scheme.min_factor), scheme.max_factor)     # new arrays: out= costs more
        if not calm:
            reject = ~accept
            if reject.any():
                rejected += int(np.count_nonzero(reject & ~done))
        prop = size * factor
    else:
        raise DivergenceError(f"{name} did not finish in {max_iterations} iterations")
    return _finish(name, out, x0.device, nfev, rejected, bad_time, stats, rtol, atol, max_norm)


def _finish(name, out: np.ndarray, device, nfev: int, rejected: int, bad_time: np.ndarray, stats, rtol, atol,
            max_norm) -> torch.Tensor:
    """The rollout ``out`` as a tensor on ``device``, ``stats`` filled; a ``DivergenceError`` naming every row
    with a time in ``bad_time`` (NaN: the row finished)."""
    if stats is not None:
        stats.update(nfev=nfev, rejected=rejected)
    diverged = np.flatnonzero(~np.isnan(bad_time)).tolist()
    if diverged:
        raise divergence_error(f"{name} (rtol={rtol}, atol={atol}, max_norm={max_norm})", diverged,
                               bad_time[diverged].tolist())
    return torch.from_numpy(out).to(device)
