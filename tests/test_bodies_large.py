"""Many bodies past what a dense pair matrix holds: hnn.orbits.nbody's blocked pair sums against its dense ones,
the pair kind's chunked network against one chunk, and the named error of a call that cannot fit."""
import math

import pytest
import torch

from hnn.bodies import Bodies
from hnn.models import pair
from hnn.models.pair import PairHNN, TooManyPairsError
from hnn.orbits import nbody

EPS = torch.finfo(torch.float64).eps


def _spread_states(count: int, batch: int = 3, seed: int = 0) -> torch.Tensor:
    """``(batch, 4 count)`` states with positions spread over a disk of radius ~ sqrt(count) (no close pair)."""
    g = torch.Generator().manual_seed(seed)
    return torch.randn(batch, 4 * count, generator=g, dtype=torch.float64) * math.sqrt(count)


def _dense(monkeypatch, f, *args):
    """``f(*args)`` with the dense incidence path forced (every count below the threshold)."""
    with monkeypatch.context() as m:
        m.setattr(nbody, "DENSE_BODIES", 10 ** 6)
        return f(*args)


@pytest.mark.parametrize("softening", [0.0, 0.1])
def test_blocked_gravity_agrees_with_the_dense_pair_matrix(monkeypatch, softening):
    count = 90                                      # past DENSE_BODIES: the blocked path
    assert count > nbody.DENSE_BODIES
    x = _spread_states(count)
    field, energy = nbody.dynamics(x, softening), nbody.hamiltonian(x, softening)
    dense_field = _dense(monkeypatch, nbody.dynamics, x, softening)
    dense_energy = _dense(monkeypatch, nbody.hamiltonian, x, softening)
    # the same terms summed in another order: each sum of n terms is off by at most n eps times the sum of their
    # sizes (the pulls: |q_j - q_i| / r^3 = 1 / r^2; the potential's: 1 / r, each pair counted twice here)
    q = x[:, :2 * count].reshape(3, 2, count)
    r2 = ((q[:, :, :, None] - q[:, :, None, :]) ** 2).sum(1) + softening ** 2
    r2 = r2 + torch.diag(torch.full((count,), math.inf, dtype=torch.float64))
    pulls = (1 / r2).sum(-1)                                                   # (3, count): sum_j 1 / r_ij^2
    bound = 4 * count * EPS * torch.cat([x[:, 2 * count:].abs(), pulls, pulls], dim=1)
    assert ((field - dense_field).abs() <= bound).all()
    potential_terms = r2.rsqrt().sum(dim=(1, 2))
    assert ((energy - dense_energy).abs() <= 4 * count ** 2 * EPS * (potential_terms + x[:, 2 * count:].pow(2).sum(1))).all()
    assert torch.equal(nbody.min_separation(x), _dense(monkeypatch, nbody.min_separation, x))    # a min is exact
    # Newton's third law: the pulls cancel over the bodies (to the round-off of the sums)
    total = field[:, 2 * count:].reshape(3, 2, count).sum(-1)
    assert (total.abs() <= 4 * count * EPS * pulls.sum(-1, keepdim=True)).all()


def test_the_block_size_changes_no_number(monkeypatch):
    x = _spread_states(80)
    field = nbody.dynamics(x, 0.1)
    monkeypatch.setattr(nbody, "BLOCK_BYTES", 1)           # one body a block
    one_row = nbody.dynamics(x, 0.1)
    q = x[:, :160].reshape(3, 2, 80)
    r2 = ((q[:, :, :, None] - q[:, :, None, :]) ** 2).sum(1) + 0.01 + torch.diag(torch.full((80,), math.inf))
    pulls = (1 / r2).sum(-1)
    bound = 4 * 80 * EPS * torch.cat([x[:, 160:].abs(), pulls, pulls], dim=1)
    assert ((field - one_row).abs() <= bound).all()


def test_a_gravity_call_past_memory_says_how_much_it_needs(monkeypatch):
    monkeypatch.setattr(nbody, "PAIR_BYTES", 2 ** 12)
    with pytest.raises(TooManyPairsError, match=r"3 states of 100 bodies need about .* GiB"):
        nbody.dynamics(_spread_states(100))
    assert issubclass(TooManyPairsError, MemoryError)


def test_the_pair_network_in_chunks_gives_one_chunks_h_and_field(monkeypatch):
    torch.manual_seed(0)
    model = PairHNN(Bodies(5, 2), hidden_dim=16).double()
    layout = Bodies(40, 2)
    g = torch.Generator().manual_seed(1)
    x = layout.join(torch.randn(3, 40, 2, generator=g, dtype=torch.float64) * 3,
                    torch.randn(3, 40, 2, generator=g, dtype=torch.float64))
    H, field = model.hamiltonian(x).detach(), model.time_derivative(x).detach()
    i, j = pair.pair_index(40)
    with torch.no_grad():
        r = torch.linalg.vector_norm(layout.split(x)[0][:, i] - layout.split(x)[0][:, j], dim=-1)
        sizes = model.radial(r).abs().sum(1)                          # the pair terms' sizes
    monkeypatch.setattr(pair, "CHUNK_BYTES", 3 * 16 * 3 * 8 * 50)    # 50 pairs a chunk: 780 pairs in 16 chunks
    assert len(model._chunks(r)) == 16
    chunked_H, chunked_field = model.hamiltonian(x).detach(), model.time_derivative(x).detach()
    # the pair sum in another order (P eps of the terms' sizes); each pair's V and V' the same arithmetic on fewer
    # rows, which a matrix product may block differently: width eps per layer, 3 layers, of the same sizes
    assert ((chunked_H - H).abs() <= (len(i) + 3 * 16) * EPS * sizes).all()
    torch.testing.assert_close(chunked_field, field, rtol=(len(i) + 3 * 16) * EPS, atol=(len(i) + 3 * 16) * EPS)
    # training through a chunked field: the loss's gradient reaches every weight
    model.zero_grad()
    model.time_derivative(x).pow(2).sum().backward()
    assert all(p.grad is not None and torch.isfinite(p.grad).all() for p in model.radial_net.parameters())
