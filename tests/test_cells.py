"""The cell list (hnn.cells): the pairs it finds within a cutoff are exactly the all-pairs filter's, on random
clouds in 1-D, 2-D and 3-D, on bodies sitting on the cells' edges, across an empty region, over a batch's union,
and with a body that cannot be binned."""
import pytest
import torch

from hnn.bodies import Bodies
from hnn.cells import pairs_within


def _brute(q, cutoff):
    """Every pair i < j closer than ``cutoff`` in some state, by the all-pairs filter (triu order)."""
    i, j = torch.triu_indices(q.shape[1], q.shape[1], offset=1)
    r = torch.linalg.vector_norm(q[:, i] - q[:, j], dim=-1)
    keep = (r < cutoff).any(dim=0)
    return i[keep], j[keep]


def _same(q, cutoff):
    got, want = pairs_within(q, cutoff), _brute(q, cutoff)
    assert torch.equal(got[0], want[0]) and torch.equal(got[1], want[1]), (len(got[0]), len(want[0]))
    return len(want[0])


@pytest.mark.parametrize("dim", [1, 2, 3])
@pytest.mark.parametrize("seed", range(6))
def test_random_clouds_give_the_all_pairs_filters_pairs(dim, seed):
    g = torch.Generator().manual_seed(seed)
    count = int(torch.randint(20, 300, (1,), generator=g))
    batch = int(torch.randint(1, 4, (1,), generator=g))
    # about one body per 3.4 units of volume, a cutoff of 1 to 3: a few to a few dozen partners each
    q = (torch.rand(batch, count, dim, generator=g, dtype=torch.float64) - 0.3) * 1.5 * count ** (1 / dim)
    cutoff = 1 + 2 * float(torch.rand(1, generator=g))
    found = _same(q, cutoff)
    # the check can fail: the clouds hold pairs inside the cutoff and pairs beyond it
    assert 0 < found < count * (count - 1) // 2


@pytest.mark.parametrize("dim", [2, 3])
def test_bodies_on_the_cells_edges(dim):
    # a grid of spacing exactly the cutoff: every body on a cell's edge, its axis neighbours exactly r_c away (not
    # closer: not a pair), its diagonal ones beyond; then nudged by 1e-9 either way, a pair appears or stays out
    cutoff = 1.25
    axes = torch.meshgrid(*[torch.arange(5, dtype=torch.float64)] * dim, indexing="ij")
    grid = torch.stack(axes, dim=-1).reshape(1, -1, dim) * cutoff
    assert _same(grid, cutoff) == 0
    assert _same(grid, cutoff * (1 + 1e-9)) == dim * 4 * 5 ** (dim - 1)       # the axis neighbours, all of them
    nudged = grid.clone()
    nudged[0, 1, -1] -= 1e-9 * cutoff        # body 1 a hair towards body 0 (the next along the last axis)
    assert _same(nudged, cutoff) == 1
    # far from the origin the cells' round-off grows with the coordinates: the grid moved to 1e6 gives the same answer
    assert _same(nudged + 1e6, cutoff) == _same(nudged, cutoff)


@pytest.mark.parametrize("dim", [2, 3])
def test_two_clusters_across_an_empty_region(dim):
    g = torch.Generator().manual_seed(4)
    near = torch.rand(1, 60, dim, generator=g, dtype=torch.float64) * 3
    far = near + 500.0           # 200 cutoffs of nothing between them: many empty cells, none laid out
    q = torch.cat([near, far, near[:, :5] + 250.0], dim=1)
    found = _same(q, 2.5)
    assert found > 0


def test_a_batch_lists_the_union_of_its_states_pairs():
    g = torch.Generator().manual_seed(5)
    q = torch.rand(3, 80, 2, generator=g, dtype=torch.float64) * 10
    union = set()
    for state in q:
        i, j = pairs_within(state[None], 1.0)
        union |= set(zip(i.tolist(), j.tolist()))
    i, j = pairs_within(q, 1.0)
    assert set(zip(i.tolist(), j.tolist())) == union and len(i) == len(union)
    _same(q, 1.0)


def test_one_body_float32_and_a_body_that_cannot_be_binned():
    assert len(pairs_within(torch.zeros(2, 1, 3), 1.0)[0]) == 0
    q = torch.rand(2, 50, 2, generator=torch.Generator().manual_seed(6)) * 6
    _same(q, 0.9)
    # a NaN body is listed with its neighbour by index, so its NaN reaches H, beside the finite pairs
    q[1, 7, 0] = float("nan")
    i, j = pairs_within(q, 0.9)
    pairs = set(zip(i.tolist(), j.tolist()))
    want = set(zip(*[t.tolist() for t in _brute(q, 0.9)]))
    assert pairs == want | {(7, 8)}


def test_a_cutoff_is_declared_with_its_pairs():
    bodies = Bodies(8, 2, pairs="cutoff", cutoff=2.5)
    assert Bodies.from_dict(bodies.to_dict()) == bodies and "closer than 2.5" in bodies.describe()
    # a layout without a cutoff is saved as before cutoffs existed (no "cutoff" key), and reads back
    assert "cutoff" not in Bodies(8, 2).to_dict() and Bodies.from_dict(Bodies(8, 2).to_dict()) == Bodies(8, 2)
    for bad in ({"pairs": "cutoff"}, {"pairs": "cutoff", "cutoff": 0.0}, {"pairs": "cutoff", "cutoff": float("inf")},
                {"pairs": "all", "cutoff": 2.5}):
        with pytest.raises(ValueError, match="cutoff"):
            Bodies(8, 2, **bad)
    with pytest.raises(ValueError, match="cutoff"):
        pairs_within(torch.zeros(1, 3, 2), -1.0)
