"""A state's layout as bodies: how many, in what dimension, in which order, and which pairs interact.

A task of several bodies declares its ``Bodies`` (its config's ``BODIES``, saved in a run's args.json as
``"bodies"`` by ``model_facts``), so that a kind reads any number of bodies from one flat state
``x = [q, p]`` ``(batch, 2 N dim)``:

    layout = Bodies(count=3, dim=2)           # the 3-body task: [qx_1..qx_3, qy_1..qy_3, px_1..px_3, py_1..py_3]
    q, p = layout.split(x)                    # (batch, N, dim) each, N read from x's width
    x = layout.join(q, p)

``order``: ``'coordinate'`` (the original orbit tasks': each half holds every body's x, then every body's y,
...) or ``'body'`` (each half holds body 1's coordinates, then body 2's, ...). q is the first half of x
(Hamilton's [q, p], as every kind reads it). ``species``: one label per body of the declared count
(bodies of one label are identical: they share a mass and may be exchanged), None for bodies that are
all alike (the orbit tasks' unit masses). ``pairs``: which pairs interact, ``'all'`` (gravity: N(N-1)/2
pairs, O(N^2) a step), ``'neighbours'`` (body i with body i + 1 only: a chain of springs, O(N) a step) or
``'cutoff'`` (the pairs closer than ``cutoff``, found at each call by a cell list, ``hnn.cells``: a short-range
scene such as a Lennard-Jones cluster, O(N) a step at a fixed density). ``cutoff``: that distance r_c, in the
positions' units, given with ``pairs='cutoff'`` only; a pair model then reads V(r) - V(r_c) below r_c and 0
beyond (the truncated and shifted potential: H stays continuous, its force jumps by V'(r_c) at r_c).
``external``: the scene has a one-body field U(q_i) as well (breaks translation and rotation invariance).

Torch-free: a ``train.py``'s ``--help`` reads a config's declaration before torch loads; ``split`` and
``join`` call only the tensors' own methods (torch tensors).
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass

ORDERS = ("coordinate", "body")
PAIRS = ("all", "neighbours", "cutoff")


@dataclass(frozen=True)
class Bodies:
    """The layout of a state of ``count`` bodies in ``dim`` spatial dimensions (see the module's docstring)."""
    count: int
    dim: int
    order: str = "coordinate"
    species: tuple[int, ...] | None = None
    pairs: str = "all"
    external: bool = False
    cutoff: float | None = None

    def __post_init__(self):
        if not isinstance(self.count, int) or self.count < 1:
            raise ValueError(f"Bodies.count must be a positive integer (the bodies of the task's states), "
                             f"got {self.count!r}")
        if self.dim not in (1, 2, 3):
            raise ValueError(f"Bodies.dim must be 1, 2 or 3 (the bodies' spatial dimension), got {self.dim!r}")
        if self.order not in ORDERS:
            raise ValueError(f"Bodies.order={self.order!r}: choose one of {', '.join(ORDERS)}")
        if self.pairs not in PAIRS:
            raise ValueError(f"Bodies.pairs={self.pairs!r}: choose one of {', '.join(PAIRS)}")
        if self.pairs == "cutoff":
            if isinstance(self.cutoff, bool) or not isinstance(self.cutoff, (int, float)) \
                    or not math.isfinite(self.cutoff) or self.cutoff <= 0:
                raise ValueError(f"Bodies(pairs='cutoff') interacts the pairs closer than cutoff, a finite distance "
                                 f"> 0: got cutoff={self.cutoff!r}; give one, e.g. Bodies(..., pairs='cutoff', "
                                 "cutoff=2.5)")
            object.__setattr__(self, "cutoff", float(self.cutoff))
        elif self.cutoff is not None:
            raise ValueError(f"Bodies(cutoff={self.cutoff!r}) with pairs={self.pairs!r}: a cutoff belongs to "
                             "pairs='cutoff' (declare that), or leave cutoff=None")
        if self.species is not None:
            species = tuple(int(s) for s in self.species)
            if len(species) != self.count or min(species) < 0:
                raise ValueError(f"Bodies.species gives a label >= 0 to each of the {self.count} bodies, "
                                 f"got {self.species!r}")
            object.__setattr__(self, "species", species)

    @property
    def width(self) -> int:
        """The width of a state of the declared bodies, 2 N dim."""
        return 2 * self.count * self.dim

    @property
    def num_species(self) -> int:
        """How many kinds of body (1 where all are alike)."""
        return 1 if self.species is None else max(self.species) + 1

    def count_of(self, width: int) -> int:
        """The number of bodies in a state of ``width`` columns (any count: a pair model reads every N)."""
        if not isinstance(width, int) or width < 2 * self.dim or width % (2 * self.dim):
            raise ValueError(f"a state of bodies in {self.dim}-D has a width 2 N {self.dim}; got {width} columns")
        return width // (2 * self.dim)

    def labels(self, count: int) -> list[int]:
        """The species label of each of ``count`` bodies: the declared ones at the declared count; all 0 where
        the bodies are all alike (any count); else a ValueError (which body is which is unknown)."""
        if self.species is None:
            return [0] * count
        if count != self.count:
            raise ValueError(f"the task declares {self.count} bodies of {self.num_species} species; a state of "
                             f"{count} bodies does not say which is which: declare Bodies(species=None) for "
                             "identical bodies, or evaluate at the declared count")
        return list(self.species)

    def split(self, x):
        """``(q, p)``, each ``(batch, N, dim)``, of states ``x`` ``(batch, 2 N dim)``."""
        n = self.count_of(x.shape[-1])
        halves = x.reshape(x.shape[0], 2, *((self.dim, n) if self.order == "coordinate" else (n, self.dim)))
        if self.order == "coordinate":
            halves = halves.transpose(2, 3)
        return halves[:, 0], halves[:, 1]

    def flat(self, v):
        """One half ``(batch, N * dim)`` in the declared order of per-body vectors ``v`` ``(batch, N, dim)``."""
        return (v.transpose(1, 2) if self.order == "coordinate" else v).reshape(v.shape[0], -1)

    def bodywise(self, half):
        """Per-body vectors ``(batch, N, dim)`` of one half ``(batch, N * dim)`` in the declared order."""
        n = half.shape[-1] // self.dim
        if self.order == "coordinate":
            return half.reshape(half.shape[0], self.dim, n).transpose(1, 2)
        return half.reshape(half.shape[0], n, self.dim)

    def join(self, q, p):
        """The states ``(batch, 2 N dim)`` of positions ``q`` and momenta ``p``, each ``(batch, N, dim)``."""
        half = self.flat(q)
        out = half.new_empty(half.shape[0], 2 * half.shape[1])     # a tensor's own method: no torch import here
        out[:, :half.shape[1]] = half
        out[:, half.shape[1]:] = self.flat(p)
        return out

    def to_dict(self) -> dict:
        """JSON-ready (args.json): ``from_dict`` reads it back."""
        out = asdict(self)
        out["species"] = None if self.species is None else list(self.species)
        if self.cutoff is None:     # the layouts without one are saved as they were before cutoffs existed
            del out["cutoff"]
        return out

    @classmethod
    def from_dict(cls, values: Mapping | Bodies) -> Bodies:
        """The layout a run's args recorded (``to_dict``'s), or ``values`` itself if it is one."""
        if isinstance(values, Bodies):
            return values
        if not isinstance(values, Mapping):
            raise TypeError(f"a bodies layout is a Bodies or its to_dict(), got {values!r}")
        species = values.get("species")
        return cls(**{**values, "species": None if species is None else tuple(species)})

    def describe(self) -> str:
        """One line for a reader: ``'3 bodies in 2-D, coordinate order, all pairs'``."""
        kinds = "alike" if self.species is None else f"of {self.num_species} species"
        pairs = {"all": "all pairs", "neighbours": "neighbours i, i + 1",
                 "cutoff": f"pairs closer than {self.cutoff:g} (a cell list)"}[self.pairs]
        return (f"{self.count} bodies in {self.dim}-D ({kinds}), {self.order} order, {pairs}"
                + (", an external field" if self.external else ""))

