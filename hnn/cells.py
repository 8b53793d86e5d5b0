"""The pairs of bodies within a cutoff, found by a cell list in O(N) a state (the short-range scenes' neighbours).

``pairs_within(q, cutoff)`` bins the positions ``q`` ``(batch, N, dim)`` into cells of side at least ``cutoff``, so a
pair closer than the cutoff sits in one cell or in two adjacent ones (their indices differ by at most 1 on each
axis), and looks for each body's partners in the 3^dim cells around its own: O(N) work a state at a fixed
density, against the N(N-1)/2 of every pair. The cells are never laid out as an array (a sparse cloud would need
many empty ones): each body carries its cell's number, the bodies are sorted by it, and a neighbour cell's
bodies are a range of that order found by ``searchsorted``. No Python loop runs over bodies or cells.

The answer is exact, the all-pairs filter's: the candidates are kept where r = |q_i - q_j| < cutoff, r computed
as ``hnn.models.pair.separations`` computes it. A batch of states gets one list, the union over its states (a
pair model evaluates every listed pair in every state and masks those at r >= cutoff: the same sum).

A body with a non-finite coordinate cannot be binned; it is listed with one other body (i and i + 1, or i - 1
for the last), so that its NaN reaches the state's energy and force as it does with every pair, never vanishes.

Shapes: positions ``(batch, N, dim)``; the pairs ``(i, j)`` ``(P,)`` each, i < j, sorted by (i, j) as
``torch.triu_indices`` lists them.
"""
from __future__ import annotations

import math

import torch

# cells per axis at most this, so that a state's cell numbers (up to MAX_CELLS^dim) times the batch stay within
# int64: a larger cloud gets larger cells (still at least the cutoff: the answer is the same, the cost grows)
MAX_CELLS = 2 ** 13


def pairs_within(q: torch.Tensor, cutoff: float) -> tuple[torch.Tensor, torch.Tensor]:
    """``(i, j)`` ``(P,)`` each: every pair i < j closer than ``cutoff`` in at least one state of positions ``q``
    ``(batch, N, dim)`` (and each non-finite body with one other; see the module's docstring)."""
    if not (isinstance(cutoff, (int, float)) and math.isfinite(cutoff) and cutoff > 0):
        raise ValueError(f"a cell list's cutoff is a finite distance > 0, got {cutoff!r}")
    if q.dim() != 3:
        raise ValueError(f"expected positions of shape (batch, N, dim), got {tuple(q.shape)}")
    batch, count, dim = q.shape
    q = q.detach()
    finite = torch.isfinite(q).all(dim=2)                                           # (batch, N)
    cell, cells = _cells(q, finite, cutoff)
    # one number per body: its state's block of cell numbers, then its cell's; a non-finite body gets -1 (no cell)
    state = torch.arange(batch, device=q.device)[:, None]
    key = torch.where(finite, state * cells.prod() + _number(cell, cells), -1).reshape(-1)
    order = torch.argsort(key)
    sorted_key = key[order]
    # each finite body's 3^dim neighbour cells (those inside the grid): the range of bodies each holds
    body = torch.nonzero(finite.reshape(-1)).squeeze(1)                             # flat index b * N + i
    shifts = torch.stack(torch.meshgrid(*[torch.tensor([-1, 0, 1], device=q.device)] * dim, indexing="ij"),
                         dim=-1).reshape(-1, dim)
    around = cell.reshape(-1, dim)[body][:, None, :] + shifts                     # (bodies, 3^dim, dim)
    inside = ((around >= 0) & (around < cells)).all(dim=2)
    wanted = (body // count)[:, None] * cells.prod() + _number(around.clamp(min=0), cells)
    start = torch.searchsorted(sorted_key, wanted).reshape(-1)
    sizes = torch.where(inside.reshape(-1), torch.searchsorted(sorted_key, wanted, right=True).reshape(-1) - start, 0)
    # every (body, partner) of those ranges, flat: the partner's place in the sorted order is its range's start
    # plus its rank within the range
    total = int(sizes.sum())
    place = torch.arange(total, device=q.device) + (start - (torch.cumsum(sizes, 0) - sizes)).repeat_interleave(
        sizes, output_size=total)
    mine = body.repeat_interleave(shifts.shape[0]).repeat_interleave(sizes, output_size=total)
    other = order[place]
    # both ends in one state (the key holds it), so i < j is their flat indices' order; the distance as
    # hnn.models.pair.separations takes it
    # (one nonzero and index_select per filter: a boolean index would find the kept places once per array)
    keep = torch.nonzero(mine < other).squeeze(1)
    mine, other = mine.index_select(0, keep), other.index_select(0, keep)
    flat = q.reshape(-1, dim)
    r = torch.linalg.vector_norm(flat.index_select(0, mine) - flat.index_select(0, other), dim=-1)
    close = torch.nonzero(r < cutoff).squeeze(1)
    found = (mine.index_select(0, close) % count) * count + other.index_select(0, close) % count
    found = torch.cat([found, _stray_pairs(finite, count)])
    found = torch.unique(found)                                                     # sorted: triu_indices' order
    return found // count, found % count


def _cells(q: torch.Tensor, finite: torch.Tensor, cutoff: float) -> tuple[torch.Tensor, torch.Tensor]:
    """``(cell, cells)``: each body's cell index on each axis ``(batch, N, dim)`` (0 for a non-finite body) and the
    cells per axis ``(dim,)``, one grid of cells of side >= ``cutoff`` from each state's own lowest corner."""
    big = torch.finfo(q.dtype).max
    low = torch.where(finite[..., None], q, big).amin(dim=1, keepdim=True)          # (batch, 1, dim)
    high = torch.where(finite[..., None], q, -big).amax(dim=1, keepdim=True)
    low = torch.where(low <= high, low, 0.0)                                        # a state without a finite body
    extent = (high - low).clamp(min=0).amax(dim=(0, 1))                             # (dim,)
    cells = torch.floor(extent / cutoff).clamp(1, MAX_CELLS).to(torch.int64)
    # (q - low) / side carries about 2 eps of the cell count of round-off: a side that much above the cutoff keeps
    # a pair closer than the cutoff in adjacent cells however the divisions round
    side = torch.maximum(extent / cells, torch.full_like(extent, cutoff))
    side = side * (1 + 8 * torch.finfo(q.dtype).eps * (cells + 1))
    offset = torch.where(finite[..., None], q - low, 0.0)
    cell = torch.floor(offset / side).to(torch.int64)
    return torch.minimum(cell.clamp(min=0), cells - 1), cells


def _number(cell: torch.Tensor, cells: torch.Tensor) -> torch.Tensor:
    """The number of each cell of indices ``cell`` ``(..., dim)`` in a grid of ``cells`` per axis, row-major."""
    strides = torch.cat([torch.cumprod(cells.flip(0), 0).flip(0)[1:], cells.new_ones(1)])
    return (cell * strides).sum(dim=-1)


def _stray_pairs(finite: torch.Tensor, count: int) -> torch.Tensor:
    """The pair numbers i * N + j of each non-finite body with its neighbour by index (i + 1, or i - 1 for the
    last body), in any state: a list of at most N."""
    if count < 2 or bool(finite.all()):
        return finite.new_zeros(0, dtype=torch.int64)
    body = torch.nonzero((~finite).any(dim=0)).squeeze(1)
    partner = torch.where(body < count - 1, body + 1, body - 1)
    return torch.minimum(body, partner) * count + torch.maximum(body, partner)
