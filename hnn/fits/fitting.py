"""One linear solve in place of the training loop. ``fit_least_squares`` is the front door for Python
users (``hnn.fit_least_squares``); ``solve`` fits a model that ``hnn.fits.build`` made, as a run does.

    model, stats = hnn.fit_least_squares("hnn", x, dxdt, fit="swim", width=1000, seed=0)
    model.hamiltonian(x)                          # H (rows,), dx/dt = J grad H
    model, stats = hnn.fit_least_squares("hnn", x, dxdt, fit="library")
    print(model.equation())                       # H = 3 - 3 cos(q) + p^2 ... as the data say

For each least-squares problem of the model (``part``): draw its features from the data where they are
drawn (by the row's ``sampler``: ``swim``, ``elm``), then stream the design rows through a QR factor
(``hnn.fits.lstsq``), chunk by chunk, and solve by the row's strategy (``hnn.fits.solves``: plain, or
thresholded as SINDy's STLSQ); a strategy of the whole model (``sindy``: pysindy, ``hnn.fits.sindy``)
takes the rows itself. All in float64; the seed decides the sampled neurons.
"""
from __future__ import annotations

import difflib
import time

import numpy as np
import torch

from ..metrics import derivative_mse
from ..progress import Ticker
from ..settings import RunSettings
from ..specs import ModelSpec
from ..trainers.rows import check_data
from ..units import Rescaled, UnitScales, in_canonical_units, refusal, units_reason
from .lstsq import RIDGES, StreamingQR, chunk_rows, chunks
from .registry import build, fitted_model, get_fit

DESIGN_BYTES = 2 ** 27  # the design rows built at once (a library's intermediate arrays are a few times this)


def _rows_per_state(part, x, y) -> int:
    A, _ = part.design(x[:1], y[:1], None)
    return len(A)


def _stream(part, x: torch.Tensor, y: torch.Tensor, weights, rcond: float, bar) -> StreamingQR:
    """The QR factor of ``part``'s design over every state, its design built once, chunk by chunk; through
    ``_stream_factored`` where the part's design factors.

    The rows go into a plain QR (no ridge, unit scales); the columns' norms are those of its factor's
    (A = Q R, Q orthogonal), so the ridged factor on unit-norm columns is then the QR of the small
    [R diag(1/norms) | Q^T y; rcond I | 0], ``(columns + rhs)`` rows more, never the rows again (which a
    library built twice, once for the norms and once for the factor)."""
    factored = part.factored() if part.factored is not None else None
    if factored is not None:
        return _stream_factored(*factored, x, y, weights, rcond, bar)
    per_state = _rows_per_state(part, x, y)
    # the design of a few states at a time: a library's terms build (states, terms, dim) arrays several times over
    step = max(1, DESIGN_BYTES // (8 * part.columns * per_state))
    plain = StreamingQR(part.columns, part.rhs)
    for start, stop in chunks(len(x), part.columns, part.rhs, per_state):
        # each piece copied into the QR's operand and freed there (no joined copy of the chunk's design)
        plain.add_blocks([part.design(x[i:min(i + step, stop)], y[i:min(i + step, stop)], weights)
                          for i in range(start, stop, step)])
        bar.advance(stop - start)
    R = plain.factor
    solver = StreamingQR(part.columns, part.rhs, R[:, :part.columns].norm(dim=0), rcond)
    solver.add(R[:, :part.columns], R[:, part.columns:], rows=plain.rows)
    return solver


def _stream_factored(slopes, V: torch.Tensor, targets: list[int], x: torch.Tensor, y: torch.Tensor, weights,
                     rcond: float, bar) -> StreamingQR:
    """The factor of a sampled layer's gradient design without building it: there the rows of component j are
    S diag(V[:, j]) (S ``(states, K)`` the neurons' slopes 1 - phi^2, V ``(K, m)`` their weights along each
    component, J and signs folded in). A QR of [S | Y] (``states`` rows) gives S = Q R_s and Z = Q^T Y, and
    then |S diag(V_j) c - y_j|^2 = |R_s diag(V_j) c - Z_j|^2 + what Q misses of y_j: the problem of
    ``states * m`` rows becomes one of ``K * m`` rows. At width 5000 on 20k 4-d states the two QRs cost
    half the direct one's arithmetic (docs/speed.md, "Least-squares fits"). A library's gradient factors as
    B C_j (B ``(states, M)`` the functions its derivatives are made of, ``V`` ``(M, K, m)``): the same with
    R_s C_j for R_s diag(V_j), M columns in the first QR (the 3-body's cubic library: 427 for 790 terms)."""
    dense = V.dim() == 3
    K, m = V.shape[-2:]
    M = V.shape[0] if dense else K
    w = torch.ones(m, dtype=torch.float64) if weights is None else \
        torch.as_tensor(weights, dtype=torch.float64)[targets]
    Y = y[:, targets]
    stage = StreamingQR(M, m)
    for start, stop in chunks(len(x), M, m):
        # in add_blocks' list, the slopes' only reference: freed once copied, before the QR (1.6 GB at width 10000)
        stage.add_blocks([(slopes(x[start:stop]), Y[start:stop])])
        bar.advance(stop - start)
    R = stage.factor
    if not dense and len(R) < M + m:
        # fewer states than the slopes' columns: R is trapezoidal, and its missing rows are zero rows of the same
        # problem, which make R_s the square triangle that add_triangular folds
        R = torch.cat([R, R.new_zeros(M + m - len(R), M + m)])
    Rs, Z, tail = R[:M, :M], R[:M, M:], R[M:, M:]
    if dense:
        V = torch.stack([Rs @ V[:, :, j] for j in range(m)], dim=2)        # R_s C_j: the rows, (M, K, m)
        scale = (V * V * w).sum(dim=(0, 2)).sqrt()
    else:
        scale = ((Rs * Rs).sum(dim=0) * (V * V * w).sum(dim=1)).sqrt()    # |A_k| over every component's rows
    solver = StreamingQR(K, 1, scale, rcond)
    if not dense:       # R_s diag(V_j) is a triangle: folded in one at a time (a fifth of a stacked QR's flops)
        for j in range(m):
            solver.add_triangular(w[j].sqrt() * Rs * V[:, j], w[j].sqrt() * Z[:, j:j + 1])
    piece = max(1, chunk_rows(K, 1) // m)
    for start in range(0, len(Rs) if dense else 0, piece):
        A = torch.cat([w[j].sqrt() * V[start:start + piece, :, j] for j in range(m)])
        Yb = torch.cat([w[j].sqrt() * Z[start:start + piece, j:j + 1] for j in range(m)])
        solver.add(A, Yb, rows=0)
    solver.rows = len(x) * m
    solver.outside = (w * (tail * tail).sum(dim=0)).sum().reshape(1)
    return solver


def _draw(part, sampler, x: torch.Tensor, y: torch.Tensor, rng: np.random.Generator, values) -> None:
    """Set a drawn layer's neurons from the states this part reads by ``sampler`` (the fit row's; SWIM
    supervised by ``values``, the function's values, where the part takes them: H for an HNN, dx/dt for a
    field; ELM reads none)."""
    z = part.inputs(x).numpy()
    supervise = (values if values is not None else y.numpy() if part.rhs > 1 else None) if part.supervised else None
    part.features.set(*sampler(z, part.features.width, rng, supervise))


def solve(model, x, dxdt, test_x=None, test_dxdt=None, *, fit: str = "swim", seed: int = RunSettings.seed,
          rcond=RunSettings.fit_rcond, threshold: float = RunSettings.library_threshold, loss_weights=None,
          values=None, anchor=None, progress: bool | None = None) -> dict:
    """Fit ``model`` (``hnn.fits.build``'s, of fit ``fit``) to ``dxdt`` at ``x`` ``(rows, dim)`` in place.

    ``seed`` draws the sampled neurons; ``rcond``: the ridge relative to the design's unit-norm columns, or
    ``'auto'``: each problem's own, chosen by generalized cross-validation (``hnn.fits.lstsq.StreamingQR.ridge``);
    ``threshold``: a library's smallest coefficient kept; ``loss_weights`` ``(dim,)``: each component's
    weight in the squared error (``hnn.balance``); ``values`` ``(rows,)``: H at ``x`` where known, which
    SWIM then samples by (their supervised SWIM; without it pairs are uniform, their U-SWIM); ``anchor``
    ``(x0 (dim,), H0)``: the one H value that fixes H's constant (default: the constant is 0).

    Returns the stats ``hnn.train`` returns (one final ``train_loss`` and ``test_loss``, ``seconds``: the
    fit's wall time) and ``"fit"``: what it did (the fit, rows, terms kept, and for a library its equation).
    """
    row = get_fit(fit)
    if not row.solved:
        raise ValueError("fit='adam' trains with hnn.train; solve() fits by least squares: swim, elm, library or sindy")
    width = model.input_dim
    x, dxdt = (check_data(name, a, width=width, dtype=torch.float64) for name, a in (("x", x), ("dxdt", dxdt)))
    if len(x) != len(dxdt):
        raise ValueError(f"x has {len(x)} rows but dxdt has {len(dxdt)}")
    if len(x) < 2:
        raise ValueError(f"a least-squares fit needs at least 2 states, got {len(x)}")
    if values is not None:
        values = np.asarray(values, dtype=np.float64).reshape(len(x), -1)
    weights = None if loss_weights is None else torch.as_tensor(loss_weights, dtype=torch.float64)
    info = {"fit": fit, "rows": len(x), "seed": seed}
    rng = np.random.default_rng(seed)
    tic = time.perf_counter()
    if row.solve.whole is not None:         # a strategy of the whole model (SINDy's pysindy)
        info.update(row.solve.whole(model, x, dxdt, threshold))
    else:
        parts = model.parts()
        with Ticker(len(x) * len(parts), f"fit {fit}", progress, unit="state") as bar:
            for part in parts:
                if part.features is not None and part.features.drawn:
                    _draw(part, row.sampler, x, dxdt, rng, values)
                solver = _stream(part, x, dxdt, weights, RIDGES[0] if rcond == "auto" else rcond, bar)
                ridge = solver.ridge() if rcond == "auto" else None
                part.assign(row.solve.coefficients(solver, threshold, ridge))
                if ridge is not None:
                    info.setdefault("ridge", {})[part.name] = [float(r) for r in ridge]
        info["rcond"] = rcond
    if anchor is not None:
        if not hasattr(model, "anchor"):
            raise ValueError(f"anchor=(x0, H0) fixes an H's constant; the {type(model).__name__} has no H")
        x0 = check_data("anchor x0", torch.as_tensor(anchor[0], dtype=torch.float64).reshape(1, -1), width=width,
                        dtype=torch.float64)
        model.anchor(x0, anchor[1])
    seconds = time.perf_counter() - tic
    if row.solve.sparse:        # some features kept, the rest dropped: how many, and the equation they make
        info["terms"] = int(sum(int((p != 0).sum()) for name, p in model.named_parameters() if "coef" in name))
    if row.prints_equation:
        info["equation"] = model.equation()
    stats = {"train_loss": [derivative_mse(model, x, dxdt)[0]], "test_loss": [], "test_steps": [], "seconds": seconds,
             "fit": info}
    if test_x is not None:
        stats["test_loss"] = [derivative_mse(model, check_data("test_x", test_x, width=width, dtype=torch.float64),
                                             check_data("test_dxdt", test_dxdt, width=width, dtype=torch.float64))[0]]
        stats["test_steps"] = [0]
    return stats


def fit_least_squares(model, x, dxdt, test_x=None, test_dxdt=None, *, fit: str = "swim",
                      width: int = RunSettings.hidden_dim, degree: int = RunSettings.library_degree,
                      frequencies: int = RunSettings.library_frequencies, seed: int = RunSettings.seed,
                      rcond=RunSettings.fit_rcond, threshold: float = RunSettings.library_threshold,
                      loss_weights=None, values=None, anchor=None, units: str = RunSettings.units,
                      bodies=None, softening: float = 0.0, progress: bool | None = None):
    """``(model, stats)``: a model of ``dxdt`` at ``x`` ``(rows, 2n)`` found by one least-squares solve.

    ``model``: a kind (``'hnn'``, ``'separable'``, ``'baseline'``, ``'pairwise'``; ``hnn.fits.FITS[fit].kinds``),
    built here with ``width`` sampled neurons (``fit='swim'`` or ``'elm'``) or the library of polynomials to
    ``degree`` (H's to ``degree + 1``) and trig terms of q to ``frequencies`` (``'library'``, ``'sindy'``); or
    a model ``hnn.fits.build`` made (wrap it in ``hnn.units.Rescaled`` to let ``units`` rescale it).
    ``bodies``: the pair kind's layout of ``x``'s columns (an ``hnn.bodies.Bodies`` or its dict: count, dimension,
    order), which it needs; a task's is its Config's ``BODIES``. The pair kind reads distances, which no
    scale per column keeps: it fits the data as they are, and refuses data the units rule would rescale.
    ``softening``: a Plummer-softened scene's length e (the gravity task's ``--softening``, in x's units of
    length): the radial library then holds 1/sqrt(r^2 + e^2), as the command's fit of that task does.

    ``units``: ``hnn.train``'s rule, by the same function (``hnn.units.in_canonical_units``): ``'auto'`` fits a
    kind named here in the canonical units of ``x``, ``dxdt`` where their sizes lie far from 1 (or their
    columns' sizes spread; ``hnn.units.rescale_reason``), so that ``threshold`` (a library's smallest
    coefficient kept) and the sampled neurons' bends are relative to the data's scale, and the model
    answers in the user's units (an ``hnn.units.Rescaled``; its ``equation()`` too, the scaling undone
    exactly); ``'on'`` always; ``'off'`` fits the data as they are. A plain built model on data the rule
    would rescale is refused with the fix, as ``hnn.train`` refuses it. ``anchor`` ``(x0, H0)`` and
    ``values`` (H at ``x``) are in the user's units; ``loss_weights`` in those of the fit (as ``hnn.train``'s).
    The rest as ``solve``. The model answers through the model interface: ``time_derivative``, ``hamiltonian``
    (hnn, separable), ``equation()`` (a library's), and rolls out with ``hnn.rollout``; float64.

    ``stats``: ``solve``'s, its ``train_loss`` and ``test_loss`` those of the returned model in the user's units,
    and ``'unit_scales'`` where ``units`` rescaled the fit.
    """
    get_fit(fit)
    plain = isinstance(model, str)
    if plain:
        _check_kind(model, fit)
        x = check_data("x", x, dtype=torch.float64)
        kind = model
        model = build(ModelSpec(kind=kind, input_dim=x.shape[1], hidden_dim=width, fit=fit, library_degree=degree,
                                library_frequencies=frequencies, bodies=_layout(kind, bodies), softening=softening))
        why = refusal(model)
        if why is None:
            model = Rescaled(model)
        else:
            reason = units_reason(units, x, check_data("dxdt", dxdt, width=x.shape[1], dtype=torch.float64))
            if reason is not None:
                raise ValueError(f"units={units!r}: x and dxdt are {reason}, and the {kind} kind cannot be "
                                 f"rescaled: {why}; give the data in units near 1, or pass units='off' to fit them "
                                 "as they are")
            units = "off"
    dim = model.input_dim
    given = [None if a is None else check_data(name, a, width=dim, dtype=torch.float64)
             for name, a in (("x", x), ("dxdt", dxdt), ("test_x", test_x), ("test_dxdt", test_dxdt))]
    inner, *arrays = in_canonical_units(model, units, *given, caller="hnn.fit_least_squares")
    scales = model.scales if isinstance(model, Rescaled) else None
    if scales is not None:
        c, energy = scales.state(inner.coordinates, dim), scales.energy
        if anchor is not None:
            anchor = (torch.as_tensor(anchor[0], dtype=torch.float64).reshape(-1) / c, float(anchor[1]) / energy)
        if values is not None:
            values = np.asarray(values, dtype=np.float64) / energy
    stats = solve(inner, *arrays, fit=fit, seed=seed, rcond=rcond, threshold=threshold, loss_weights=loss_weights,
                  values=values, anchor=anchor, progress=progress)
    if scales is None:
        return model.eval(), stats
    if plain and scales == UnitScales(1.0, 1.0, 1.0):     # the rule left the data as they are: the model itself
        return inner.eval(), stats
    model.eval()
    stats["unit_scales"] = scales.to_dict()
    stats["train_loss"] = [derivative_mse(model, given[0], given[1])[0]]
    if given[2] is not None:
        stats["test_loss"] = [derivative_mse(model, given[2], given[3])[0]]
    if "equation" in stats["fit"]:
        stats["fit"]["equation"] = model.equation()
    return model, stats


def _layout(kind: str, bodies):
    """``bodies`` as a ``ModelSpec`` carries it (a dict), or None; a ValueError naming the missing layout and the fix
    where the kind reads bodies and none is given, or where one is given to a kind that reads none."""
    from ..bodies import Bodies

    reads = fitted_model(kind).reads_bodies
    if bodies is None:
        if reads:
            raise ValueError(f"the {kind} kind reads x as bodies and needs their layout: pass bodies="
                             "hnn.bodies.Bodies(count=N, dim=d) (N bodies in d dimensions, x's columns "
                             "[q of every body, then p]; order='body' where each body's coordinates sit together)")
        return None
    if not reads:
        raise ValueError(f"bodies= is the layout of a kind that reads bodies (pairwise); the {kind} kind reads x as "
                         "it is: drop bodies")
    return Bodies.from_dict(bodies).to_dict()


def _check_kind(kind: str, fit: str) -> None:
    """A ValueError in ``fit_least_squares``' words where ``kind`` is no model kind, or one ``fit`` cannot solve."""
    from ..kinds import MODEL_KINDS

    takes = get_fit(fit).kinds or tuple(MODEL_KINDS)
    if kind in takes:
        return
    if kind not in MODEL_KINDS:
        close = difflib.get_close_matches(kind, list(MODEL_KINDS), n=1, cutoff=0.6)
        raise ValueError(f"unknown kind {kind!r}; the kinds are {', '.join(MODEL_KINDS)}, and fit={fit!r} fits "
                         f"{', '.join(takes)}" + (f"; did you mean {close[0]!r}?" if close else ""))
    only = get_fit(fit).only
    why = (f"{only}: pass {' or '.join(repr(k) for k in takes)}" if only else
           f"solves the last weights of {', '.join(takes)}, whose field is linear in them, and the {kind} kind's is "
           f"not: pass one of those kinds, or train {kind!r} with hnn.train")
    raise ValueError(f"fit={fit!r} {why}")
