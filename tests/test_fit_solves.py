"""The least-squares solves behind the fits (hnn.fits.lstsq, the factored designs of hnn.fits.fitting) against
independent solves of the same problems: numpy's ``lstsq`` on the design rows built from the features'
Jacobians, and SINDy's sequential thresholding written out on those rows. Round-off bounds: the problems here
are small and well conditioned (cond(A) below 1e5), so a solution agrees to cond * eps, 1e-9 relative."""
import numpy as np
import pytest
import torch

import hnn
from hnn.fits import lstsq
from hnn.fits.features import Library, terms
from hnn.specs import ModelSpec

AGREE = 1e-9        # cond(A) * float64 eps of these small problems, with room for the thresholded re-solves


def _direct(monkeypatch):
    """Switch the factored solves off: every part streams its (state, component) rows."""
    part = hnn.fits.models.Part
    monkeypatch.setattr(hnn.fits.models, "Part", lambda *a, **k: part(*a, **{**k, "factored": None}))


def _pendulum(rows=400, seed=0):
    """States of a pendulum (q in [-3, 3], p in [-2, 2]) and dx/dt of H = p^2 / 2 - 3 cos q + 0.3 q^2 p^2."""
    rng = np.random.default_rng(seed)
    q, p = rng.uniform(-3, 3, rows), rng.uniform(-2, 2, rows)
    return np.column_stack([q, p]), np.column_stack([p + 0.6 * q ** 2 * p, -3 * np.sin(q) - 0.6 * q * p ** 2])


@pytest.mark.parametrize("width, form, degree, frequencies, products", [
    (12, "hamiltonian", 2, 1, True), (2, "hamiltonian", 3, 2, True), (4, "hamiltonian", 2, 1, True),
    (3, "potential", 3, 1, False), (2, "kinetic", 3, 0, False)])
def test_a_librarys_gradient_factors_are_its_jacobian(width, form, degree, frequencies, products):
    """d theta_k / d x_i = sum_m basis_m(x) C[m, k, i], to round-off of the product rule (a few eps of the
    largest entry), with fewer basis functions than terms."""
    library = Library(terms(width, form, degree, frequencies, products), width)
    basis, C = library.gradient_factors()
    x = torch.as_tensor(np.random.default_rng(1).uniform(-2, 2, size=(64, width)))
    jac = library.jacobian(x)
    assert C.shape[:2] == (basis(x).shape[1], library.width) and C.shape[0] < library.width
    assert torch.allclose(torch.einsum("rm,mki->rki", basis(x), C), jac, rtol=0, atol=1e-13 * jac.abs().max())


def test_the_3body_cubic_library_factors_through_427_functions():
    """The count docs/speed.md quotes: 790 terms of H on 12 columns, 427 functions in their derivatives."""
    library = Library(terms(12, "hamiltonian", 2, 1), 12)
    basis, C = library.gradient_factors()
    assert (library.width, C.shape[0]) == (790, 427)


@pytest.mark.parametrize("kind", ["hnn", "separable"])
def test_a_librarys_factored_fit_is_lstsq_on_its_rows(kind, monkeypatch):
    """threshold 0 (every term kept), a fixed ridge rcond on unit columns: the factored fit, the direct stream of
    the rows and numpy's lstsq of the stacked [A / scale; rcond I] agree."""
    x, dxdt = _pendulum()
    rcond = 1e-12
    spec = ModelSpec(kind=kind, input_dim=2, fit="library", library_degree=3, library_frequencies=1)
    fitted = hnn.fits.build(spec)
    hnn.fits.solve(fitted, x, dxdt, fit="library", rcond=rcond, threshold=0.0, progress=False)
    ours = torch.cat([p.reshape(-1) for n, p in fitted.named_parameters() if "coef" in n]).numpy()
    truth = []
    for part in hnn.fits.build(spec).parts():
        A, Y = (a.numpy() for a in part.design(torch.as_tensor(x), torch.as_tensor(dxdt), None))
        scale = np.linalg.norm(A, axis=0)
        stacked = np.vstack([A / scale, rcond * np.eye(A.shape[1])])
        truth.append(np.linalg.lstsq(stacked, np.vstack([Y, np.zeros((A.shape[1], 1))]), rcond=None)[0][:, 0] / scale)
    order = {"hnn": [0], "separable": [0, 1]}[kind]     # FittedSeparable's parameters: kinetic, then potential
    truth = np.concatenate([truth[i] for i in order])
    assert np.abs(ours - truth).max() <= AGREE * np.abs(truth).max()
    _direct(monkeypatch)
    direct = hnn.fits.build(spec)
    hnn.fits.solve(direct, x, dxdt, fit="library", rcond=rcond, threshold=0.0, progress=False)
    z = torch.as_tensor(x)
    assert torch.allclose(fitted.time_derivative(z), direct.time_derivative(z), rtol=AGREE, atol=AGREE)


def _stlsq(A, y, threshold, lam):
    """SINDy's STLSQ on the rows: lstsq of the kept columns of A (unit-scaled) with the ridge lam, drop those below
    ``threshold`` in data units, again until none drops; the coefficients in data units."""
    scale = np.linalg.norm(A, axis=0)
    keep = np.ones(A.shape[1], dtype=bool)
    while True:
        k = int(keep.sum())
        stacked = np.vstack([A[:, keep] / scale[keep], lam * np.eye(k)])
        coef = np.linalg.lstsq(stacked, np.concatenate([y, np.zeros(k)]), rcond=None)[0] / scale[keep]
        small = np.abs(coef) < threshold
        if not small.any():
            out = np.zeros(A.shape[1])
            out[keep] = coef
            return out
        keep[np.flatnonzero(keep)[small]] = False


@pytest.mark.parametrize("lam", [1e-13, 1e-3])
def test_thresholding_on_the_small_factor_is_stlsq_on_the_rows(lam):
    """The re-solves on the last factor keep the terms and the coefficients of STLSQ re-solved on the rows each
    time, with the factor's own ridge and with a larger one (cross-validation's), over several drops."""
    rng = np.random.default_rng(3)
    A = rng.normal(size=(300, 40)) * rng.uniform(0.5, 3, size=40)
    truth = np.where(rng.uniform(size=40) < 0.4, rng.normal(size=40), 0.0)
    truth[:6] = [0.02, -0.04, 0.06, 0.09, -0.15, 0.3]      # near the threshold: dropped over several passes
    y = A @ truth + 0.01 * rng.normal(size=300)
    solver = lstsq.StreamingQR(40, 1, torch.as_tensor(np.linalg.norm(A, axis=0)), 1e-13)
    solver.add(torch.as_tensor(A), torch.as_tensor(y[:, None]))
    ours = solver.sparse(0.05, torch.tensor([lam], dtype=torch.float64))[:, 0].numpy()
    expected = _stlsq(A, y, 0.05, lam)
    assert ((ours != 0) == (expected != 0)).all() and 0 < (expected != 0).sum() < 40
    assert np.abs(ours - expected).max() <= AGREE * np.abs(expected).max()


def test_a_ridged_solve_is_lstsq_with_the_ridge_rows():
    """``solve(ridge)`` above the factor's rcond: the stacked [A / scale; lam I] of each right-hand side."""
    rng = np.random.default_rng(6)
    A, Y = rng.normal(size=(200, 25)), rng.normal(size=(200, 2))
    scale = np.linalg.norm(A, axis=0)
    solver = lstsq.StreamingQR(25, 2, torch.as_tensor(scale), 1e-13)
    solver.add(torch.as_tensor(A), torch.as_tensor(Y))
    ridge = torch.tensor([1e-2, 1e-1], dtype=torch.float64)
    ours = solver.solve(ridge).numpy()
    for j, lam in enumerate(ridge.tolist()):
        stacked = np.vstack([A / scale, lam * np.eye(25)])
        truth = np.linalg.lstsq(stacked, np.concatenate([Y[:, j], np.zeros(25)]), rcond=None)[0] / scale
        assert np.abs(ours[:, j] - truth).max() <= AGREE * np.abs(truth).max()


@pytest.mark.parametrize("rcond", [0.0, 1e-10])
def test_folding_triangles_is_the_qr_of_their_stacked_rows(rcond):
    """``add_triangular`` (LAPACK's dtpqrt) after rows added by ``add``: the solution and the residual of numpy's
    lstsq on every row stacked, ridge rows included; the first fold onto an empty factor too (rcond 0)."""
    rng = np.random.default_rng(8)
    K = 30
    scale = rng.uniform(0.5, 2, size=K)
    dense, Yd = rng.normal(size=(50, K)), rng.normal(size=(50, 1))
    triangles = [(np.triu(rng.normal(size=(K, K))), rng.normal(size=(K, 1))) for _ in range(3)]
    for first_dense in (True, False):
        solver = lstsq.StreamingQR(K, 1, torch.as_tensor(scale), rcond)
        if first_dense:
            solver.add(torch.as_tensor(dense), torch.as_tensor(Yd))
        for T, y in triangles:
            solver.add_triangular(torch.as_tensor(T), torch.as_tensor(y))
        rows = ([dense] if first_dense else []) + [T for T, _ in triangles]
        rhs = ([Yd] if first_dense else []) + [y for _, y in triangles]
        A = np.vstack([a / scale for a in rows] + [rcond * np.eye(K)])
        b = np.vstack(rhs + [np.zeros((K, 1))])
        truth, residual = np.linalg.lstsq(A, b, rcond=None)[:2]
        assert np.abs(solver.solve().numpy() * scale[:, None] - truth).max() <= AGREE * np.abs(truth).max()
        assert solver.residual().numpy() == pytest.approx(residual, rel=AGREE)


def test_cross_validation_picks_the_ridge_of_least_gcv_score_of_explicit_ridge_solves():
    """``ridge()``: for each right-hand side, the ridge of ``RIDGES`` whose solve of the stacked [B; lam I] (B the
    rows with the factor's own ridge rows) has the least rss / (1 - dof / rows)^2, dof = sum s^2 / (s^2 + lam^2)
    over B's singular values; noise of two sizes on the two right-hand sides makes them choose differently."""
    rng = np.random.default_rng(11)
    A = rng.normal(size=(120, 60)) @ np.diag(np.logspace(0, -6, 60))
    Y = np.column_stack([A @ rng.normal(size=60) + 0.003 * rng.normal(size=120),
                         A @ rng.normal(size=60) + 0.3 * rng.normal(size=120)])
    scale, rcond = np.linalg.norm(A, axis=0), 1e-13
    solver = lstsq.StreamingQR(60, 2, torch.as_tensor(scale), rcond)
    solver.add(torch.as_tensor(A), torch.as_tensor(Y))
    B = np.vstack([A / scale, rcond * np.eye(60)])
    s = np.linalg.svd(B, compute_uv=False)
    expected = []
    for j in range(2):
        b = np.concatenate([Y[:, j], np.zeros(60)])
        scores = []
        for lam in lstsq.RIDGES:
            c = np.linalg.lstsq(np.vstack([B, lam * np.eye(60)]), np.concatenate([b, np.zeros(60)]), rcond=None)[0]
            dof = (s ** 2 / (s ** 2 + lam ** 2)).sum()
            scores.append(((B @ c - b) ** 2).sum() / (1 - dof / 120) ** 2)
        expected.append(lstsq.RIDGES[int(np.argmin(scores))])
    assert solver.ridge().tolist() == expected and expected[0] < expected[1]


@pytest.mark.parametrize("form", ["field", "hamiltonian"])
def test_a_librarys_values_are_its_terms_written_out(form):
    """theta_k(x) = prod_j x_j^powers_kj * trig_k(x), in numpy, to a few eps of each value (a product of at most
    degree + 1 factors), all terms and a subset."""
    library = Library(terms(4, form, 2, 2), 4)
    x = np.random.default_rng(2).uniform(-2, 2, size=(50, 4))
    powers, trig = library.powers.numpy(), library.trig.numpy()
    angle = x[:, trig[:, 1]] * trig[:, 2]
    factor = np.where(trig[:, 0] == 1, np.sin(angle), np.where(trig[:, 0] == 2, np.cos(angle), 1.0))
    truth = np.prod(x[:, None, :] ** powers[None], axis=2) * factor
    keep = torch.arange(library.width) % 3 == 1
    for subset, expected in ((None, truth), (keep, truth[:, keep.numpy()])):
        got = library(torch.as_tensor(x), subset).numpy()
        assert np.abs(got - expected).max() <= 1e-14 * np.abs(expected).max()
    # the design's build on the transposed layout (a fit's): the same values, (terms, rows)
    transposed = library.transposed(torch.as_tensor(x)).numpy()
    assert transposed.shape == (library.width, 50)
    assert np.abs(transposed.T - truth).max() <= 1e-14 * np.abs(truth).max()


def test_a_baseline_library_fit_is_stlsq_on_lstsq_of_its_values(monkeypatch):
    """The baseline's library fit (one design, dx/dt's columns its right-hand sides, built in pieces of a few
    states each and folded in one QR) against numpy: lstsq of the terms' values written out on every column,
    thresholded as SINDy's STLSQ on the rows, each column its own terms."""
    x, dxdt = _pendulum()
    model = hnn.fits.build(ModelSpec(kind="baseline", input_dim=2, fit="library", library_degree=2,
                                     library_frequencies=1))
    # pieces of 45 states: 9 of them, copied one below the other into the QR's operand
    monkeypatch.setattr(hnn.fits.fitting, "DESIGN_BYTES", 8 * model.features.width * 45)
    hnn.fits.solve(model, x, dxdt, fit="library", rcond=0.0, threshold=0.05, progress=False)
    library = model.features
    powers, trig = library.powers.numpy(), library.trig.numpy()
    angle = x[:, trig[:, 1]] * trig[:, 2]
    A = np.prod(x[:, None, :] ** powers[None], axis=2) * np.where(trig[:, 0] == 1, np.sin(angle),
                                                                  np.where(trig[:, 0] == 2, np.cos(angle), 1.0))
    for j in range(2):
        keep = np.ones(library.width, dtype=bool)
        for _ in range(lstsq.MAX_STLSQ_ITERATIONS):
            coef = np.zeros(library.width)
            coef[keep] = np.linalg.lstsq(A[:, keep], dxdt[:, j], rcond=None)[0]
            if not (np.abs(coef[keep]) < 0.05).any():
                break
            keep &= np.abs(coef) >= 0.05
        got = model.coef[:, j].numpy()
        assert 0 < (coef != 0).sum() < library.width          # the threshold dropped terms and kept some
        assert np.array_equal(got != 0, coef != 0)
        assert np.abs(got - coef).max() <= AGREE * np.abs(coef).max()


@pytest.mark.parametrize("states, columns, rhs, per_state", [(20000, 10000, 4, 1), (80000, 427, 12, 1),
                                                             (70000, 3000, 1, 1), (9000, 1000, 1, 4)])
def test_a_streamed_qr_chunks_every_state_once_and_its_first_operand_is_no_larger_than_a_later_one(
        states, columns, rhs, per_state):
    """``chunks`` tiles the states in order; a later update stacks ``chunk_rows`` rows under the factor's
    columns + rhs, so the first chunk (no factor yet) takes that many rows more at the same peak memory, and a
    problem that fits in it is one QR (the double pendulum at width 10000: 20000 states, one chunk)."""
    bounds = lstsq.chunks(states, columns, rhs, per_state)
    assert bounds[0][0] == 0 and bounds[-1][1] == states
    assert all(a[1] == b[0] and a[0] < a[1] for a, b in zip(bounds, bounds[1:]))
    step, width = lstsq.chunk_rows(columns, rhs), columns + rhs
    operands = [(stop - start) * per_state + (width if i else 0) for i, (start, stop) in enumerate(bounds)]
    assert max(operands) <= step + width
    assert (len(bounds) == 1) == (states * per_state <= step + width)
