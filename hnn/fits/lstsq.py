"""Least squares over more rows than memory holds: a QR factor updated chunk by chunk (TSQR), in float64.

    solver = StreamingQR(columns=K, rhs=1, scale=column_norms, rcond=1e-13)
    for A, Y in chunks:                 # (rows, K), (rows, 1)
        solver.add(A, Y)
    coef = solver.solve()               # (K, 1): min |A c - Y|^2 + rcond^2 |diag(scale) c|^2
    coef = solver.sparse(threshold)     # sequentially thresholded (SINDy's STLSQ) on the same factor

Why a QR and not the normal equations: a sampled layer's features are nearly dependent (a width-1000
fit of the single pendulum keeps a third of its directions above 1e-16 of the largest), and A^T A
squares that condition. Measured on the Sampling-HNNs single pendulum (width 1000, 10k points): the
normal equations reach a relative H error of 4e-6 at best (any ridge), the QR 6e-11, numpy's SVD
``lstsq`` (their solver, ``rcond`` 1e-13) 1e-9 (docs/fits.md). The ridge rows rcond * I on the columns
scaled to unit norm stand first in the factor, so the solve is a triangular one: Tikhonov
regularization at the scale where ``lstsq``'s ``rcond`` cuts singular values.

Memory: the factor ``(K + rhs)^2`` and one chunk of rows beside it (``chunk_rows``), 8 bytes a number.
"""
from __future__ import annotations

import numpy as np
import torch
from scipy.linalg import lapack

# the stacked matrix [factor; chunk] of one QR update holds at most this many bytes (the chunk itself, the
# QR's own copy and the new factor come on top): width 5000 updates ~22k rows at a time, width 10000 10k
BLOCK_BYTES = 2 ** 30
MAX_STLSQ_ITERATIONS = 25
# the ridges generalized cross-validation chooses from (relative to unit columns; ``StreamingQR.ridge``)
RIDGES = tuple(10.0 ** e for e in range(-13, 1))


def chunk_rows(columns: int, rhs: int = 1) -> int:
    """Rows of design per QR update for ``columns`` unknowns: ``BLOCK_BYTES`` worth of [factor; chunk], at
    least as many rows as the factor (fewer would spend the update's O(K^3) on few rows), at least 1024."""
    width = columns + rhs
    return max(1024, width, BLOCK_BYTES // (8 * width) - width)


def chunks(states: int, columns: int, rhs: int = 1, per_state: int = 1) -> list[tuple[int, int]]:
    """``(start, stop)`` of each chunk of ``states`` (``per_state`` design rows each) a QR factor is streamed in:
    ``chunk_rows`` rows at a time, the first chunk ``columns + rhs`` rows more, since the factor that every later
    update stacks its rows under is not there yet (the first QR's operand no larger than a later one's: the
    same peak memory); all at once where they fit in that. The double pendulum at width 10000 (20000 states):
    one QR of 20000 x 10004 (3.3e12 flops) in place of one of 10004 rows and one of 20008 (4.7e12)."""
    step = max(1, chunk_rows(columns, rhs) // per_state)
    size, start, out = max(1, (chunk_rows(columns, rhs) + columns + rhs) // per_state), 0, []
    while start < states:
        out.append((start, min(states, start + size)))
        start, size = start + size, step
    return out


class StreamingQR:
    """min_C |A C - Y|^2 + rcond^2 |diag(scale) C|^2 over rows added in chunks (``add``), for ``columns``
    unknowns and ``rhs`` right-hand sides. ``scale`` ``(columns,)``: the columns' norms (their RMS over the
    data, or any positive size): the columns are divided by it, so ``rcond`` is relative to unit columns.
    ``rcond`` 0: a plain QR of the rows (no ridge rows), whose factor another solve reads."""

    def __init__(self, columns: int, rhs: int, scale: torch.Tensor | None = None, rcond: float = 0.0):
        if not rcond >= 0:
            raise ValueError(f"rcond must be >= 0 (the ridge that keeps a nearly dependent design solvable), "
                             f"got {rcond}")
        self.columns, self.rhs, self.rcond = columns, rhs, rcond
        scale = torch.ones(columns, dtype=torch.float64) if scale is None else scale.to(torch.float64)
        self.scale = torch.where(scale > 0, scale, torch.ones_like(scale))
        self.factor = torch.zeros(columns if rcond else 0, columns + rhs, dtype=torch.float64)
        self.factor[:, :columns] = rcond * torch.eye(columns, dtype=torch.float64)[:len(self.factor)]
        self.rows = 0                   # rows of the least-squares problem (generalized cross-validation's count)
        self.outside = torch.zeros(rhs, dtype=torch.float64)     # residual a reduced problem left behind

    def add(self, A: torch.Tensor, Y: torch.Tensor, rows: int | None = None) -> None:
        """Fold the rows ``A`` ``(rows, columns)``, ``Y`` ``(rows, rhs)`` into the factor (``rows``: how many rows of
        the original problem they stand for, where they are a reduction of more; the caller's ``A`` lives through
        the QR: ``add_blocks`` frees what only its list holds)."""
        self.add_blocks([(A, Y)], rows)

    def add_blocks(self, blocks: list, rows: int | None = None) -> None:
        """Fold the rows of every ``(A, Y)`` of ``blocks`` (as ``add``'s, one below the other) in one QR: each block
        is copied straight into the QR's operand and dropped from the list (which ends empty: a block nothing else
        holds is freed before the QR), never joined first.
        The operand is column-major, the layout LAPACK reads, so torch's QR copies it as it is (the same numbers,
        the same factor bits) rather than transposed."""
        count = sum(len(A) for A, _ in blocks)
        top = len(self.factor)
        stacked = torch.empty(self.columns + self.rhs, top + count, dtype=torch.float64).T
        stacked[:top] = self.factor
        while blocks:
            A, Y = blocks.pop(0)
            torch.div(A, self.scale, out=stacked[top:top + len(A), :self.columns])
            stacked[top:top + len(A), self.columns:] = Y.reshape(len(A), self.rhs)
            top += len(A)
            del A, Y
        self.factor = torch.linalg.qr(stacked, mode="r").R[:self.columns + self.rhs]
        self.rows += count if rows is None else rows

    def add_triangular(self, T: torch.Tensor, Y: torch.Tensor) -> None:
        """Fold the rows of an upper triangular ``T`` ``(columns, columns)`` and its ``Y`` ``(columns, rhs)`` into the
        factor (rows of a reduced problem: ``rows`` is left to the caller, as ``add(..., rows=0)``). LAPACK's
        dtpqrt folds a triangle into a triangle in 2/3 columns^3 flops, where the QR of the two stacked (``add``)
        costs 10/3 columns^3: a sampled layer's factored design is such triangles, one per component."""
        width = self.columns + self.rhs
        if T.shape != (self.columns, self.columns) or len(Y) != self.columns:
            raise ValueError(f"add_triangular takes a ({self.columns}, {self.columns}) triangle and its "
                             f"({self.columns}, {self.rhs}) right-hand sides, got {tuple(T.shape)} and {tuple(Y.shape)}")
        top = np.zeros((width, width), order="F")
        top[:len(self.factor)] = self.factor.numpy()
        block = np.empty((self.columns, width), order="F")
        block[:, :self.columns] = (T / self.scale).numpy()
        block[:, self.columns:] = Y.reshape(self.columns, self.rhs).numpy()
        # l = columns: every row of [T | Y] is zero left of its diagonal (upper trapezoidal)
        folded, _, _, info = lapack.dtpqrt(self.columns, min(64, width), top, block, overwrite_a=1, overwrite_b=1)
        if info:
            raise RuntimeError(f"LAPACK dtpqrt failed (info {info}) on a ({self.columns}, {width}) block")
        self.factor = torch.from_numpy(np.triu(folded))

    def _split(self):
        R = self.factor[:self.columns]
        return R[:, :self.columns], R[:, self.columns:]

    def residual(self) -> torch.Tensor:
        """The sum of squared residuals of each right-hand side that no coefficients can reach (``(rhs,)``)."""
        tail = self.factor[self.columns:, self.columns:]
        return (tail ** 2).sum(dim=0) + self.outside

    def ridge(self) -> torch.Tensor:
        """Each right-hand side's ridge (relative to unit columns) chosen by generalized cross-validation
        (Golub, Heath & Wahba 1979): the lam of ``RIDGES`` (at least ``rcond``) least in rss(lam) / (1 - dof(lam)
        / rows)^2, read from the SVD of the factor (its cost: width^3). Where the data are exact it picks the
        smallest; on noisy data one that stops the features from fitting the noise. ``(rhs,)``."""
        lhs, z = self._split()
        U, s, _ = torch.linalg.svd(lhs)
        zhat, floor = U.T @ z, self.residual()
        lams = torch.tensor([r for r in RIDGES if r >= self.rcond], dtype=torch.float64)
        if not len(lams):
            return torch.full((self.rhs,), self.rcond, dtype=torch.float64)
        # every ridge at once (a loop over them cost more than the SVD on a small library)
        shrink = lams[:, None] ** 2 / (s ** 2 + lams[:, None] ** 2)                     # (ridges, columns)
        rss = ((shrink[:, :, None] * zhat) ** 2).sum(dim=1) + floor                       # (ridges, rhs)
        dof = (1 - shrink).sum(dim=1)
        score = rss / (1.0 - dof / self.rows).clamp(min=1e-12)[:, None] ** 2
        return lams[score.argmin(dim=0)]        # the first (smallest) ridge of equal scores, as a loop's strict <

    def solve(self, ridge: torch.Tensor | None = None) -> torch.Tensor:
        """The coefficients ``(columns, rhs)`` of the rows added so far: with the factor's own ridge ``rcond``, or
        with each right-hand side's ``ridge`` ``(rhs,)`` on top (``ridge()``'s choice)."""
        lhs, z = self._split()
        if ridge is None or bool((ridge <= self.rcond).all()):
            scaled = torch.linalg.solve_triangular(lhs, z, upper=True)
        else:
            scaled = torch.stack([_solved(self._ridged(lhs, z[:, j], float(ridge[j]))) for j in range(self.rhs)], dim=1)
        return scaled / self.scale[:, None]

    def sparse(self, threshold: float, ridge: torch.Tensor | None = None) -> torch.Tensor:
        """Sequentially thresholded least squares (SINDy's STLSQ) on the same factor: solve, zero every
        coefficient smaller than ``threshold`` in size (in the data's units), solve again on the rest, until
        none changes; each right-hand side keeps its own terms (and its ``ridge``, as ``solve``). ``(columns, rhs)``.

        Each re-solve works on the last one's small factor, never on the rows: F = [R | Q^T y] of the kept
        columns, upper triangular ``(k + 1, k + 1)``; dropping columns is a QR of F's kept columns and its
        last (2 (k + 1) k'^2 flops, k' the columns left), which is the factor of the rows' kept columns
        (the rows = Q F, Q orthogonal: dropping columns of the rows drops those of F)."""
        if not threshold >= 0:
            raise ValueError(f"threshold must be >= 0, got {threshold}")
        lhs, z = self._split()
        out = torch.zeros(self.columns, self.rhs, dtype=torch.float64)
        for j in range(self.rhs):
            lam = self.rcond if ridge is None else float(ridge[j])
            factor = self._ridged(lhs, z[:, j], lam)
            keep = torch.arange(self.columns)
            for _ in range(MAX_STLSQ_ITERATIONS):
                coef = _solved(factor) / self.scale[keep]
                small = coef.abs() < threshold
                if not bool(small.any()):
                    break
                keep = keep[~small]
                if not len(keep):
                    coef = coef[:0]
                    break
                # the kept columns and the right-hand side (the last column), retriangularized
                factor = torch.linalg.qr(factor[:, torch.cat([(~small).nonzero()[:, 0],
                                                              torch.tensor([len(small)])])], mode="r").R
            out[keep, j] = coef
        return out

    def _ridged(self, lhs: torch.Tensor, z: torch.Tensor, lam: float) -> torch.Tensor:
        """The triangular factor ``(k + 1, k + 1)`` of min |lhs c - z|^2 + lam^2 |c|^2 in scaled units, [R | Q^T z]
        (``lhs`` ``(k, k)``: the factor, which holds rcond^2 of the ridge already): ``lhs`` itself, or with
        more ridge the QR of the stacked [lhs | z; (lam^2 - rcond^2)^(1/2) I | 0]; no singular value is cut."""
        k = lhs.shape[1]
        extra = max(lam ** 2 - self.rcond ** 2, 0.0) ** 0.5
        if not extra:       # already triangular: [lhs | z] is the factor
            return torch.cat([lhs, z[:, None]], dim=1)
        stacked = torch.zeros(len(lhs) + k, k + 1, dtype=torch.float64)
        stacked[:len(lhs), :k], stacked[:len(lhs), k] = lhs, z
        stacked[len(lhs):, :k].diagonal().fill_(extra)
        return torch.linalg.qr(stacked, mode="r").R


def _solved(factor: torch.Tensor) -> torch.Tensor:
    """The coefficients ``(k,)`` of a triangular factor [R | Q^T z] ``(k or k + 1, k + 1)``."""
    k = factor.shape[1] - 1
    return torch.linalg.solve_triangular(factor[:k, :k], factor[:k, k:], upper=True)[:, 0]
