"""The rows a trainer draws from: user arrays checked into tensors (``check_data``) and their scale
(``warn_off_scale``), a lone run's minibatch (``minibatch``), and a group's rows, padded to one stack with each
model's own sampler (``GroupRows``)."""
from __future__ import annotations

import warnings

import numpy as np
import torch

from ..units import VELOCITY_LIKE, rescale_reason


def check_data(name: str, a, width: int | None = None, dtype=torch.float32, device="cpu") -> torch.Tensor:
    """``a`` as a ``(rows, width)`` tensor, or a ValueError that names the problem and the fix."""
    t = (a if torch.is_tensor(a) else torch.as_tensor(np.asarray(a), device=device)).detach()
    if t.dim() != 2:
        raise ValueError(f"{name} must have shape (rows, dim), got {tuple(t.shape)}")
    if width is not None and t.shape[1] != width:
        raise ValueError(f"{name} has {t.shape[1]} columns but the model expects input_dim={width}; "
                         "check --input_dim against the dataset")
    if not torch.is_floating_point(t):
        t = t.to(dtype)
    bad = ~torch.isfinite(t)
    if bad.any():
        rows = torch.nonzero(bad.any(dim=1)).flatten()
        raise ValueError(f"{name} has {int(bad.sum())} NaN/inf values (first in row {int(rows[0])}, "
                         f"{len(rows)} rows affected); clean or drop those rows before training")
    return t.to(dtype=dtype, device=device)


def checked_pair(name: str, x, dxdt, kw: dict) -> tuple[torch.Tensor, torch.Tensor]:
    """``check_data`` of states ``x`` and their targets (named ``name`` and ``d<name>/dt``), of one row count
    (``kw``: ``check_data``'s width, dtype and device)."""
    target = "dxdt" if name == "x" else f"{name.split('_')[0]}_dxdt"
    x, dxdt = check_data(name, x, **kw), check_data(target, dxdt, **kw)
    if len(x) != len(dxdt):
        raise ValueError(f"{name} has {len(x)} rows but {target} has {len(dxdt)}")
    return x, dxdt


def warn_off_scale(x: torch.Tensor, dxdt: torch.Tensor, model, stacklevel: int = 3) -> None:
    """Warn when a fit of dx/dt trains on data as given that ``units='auto'`` would rescale
    (``hnn.units.rescale_reason``: the RMS of q, unless angles, of p or of either half of ``dxdt``, each over
    all of its columns, lies outside its bounds, or one part's columns spread over 10x in size). Adam's steps
    of about learn_rate and tanh's unit-wide bend suit data near unit scale: a heavy mass (p of RMS 28, dq/dt
    of 0.028) degraded a fit 40x, unwarned while only the largest column was read."""
    coordinates = "velocity" if getattr(model, "coordinates", "canonical") in VELOCITY_LIKE else "canonical"
    reason = rescale_reason(x, dxdt, bool(getattr(model, "periodic", False)), coordinates) if len(x) else None
    if reason is not None:
        warnings.warn(f"x and dxdt are {reason}; a network fits poorly there. Train hnn.units.Rescaled(model) with "
                      "units='auto' (the default), or rescale q and p so that Hamilton's equations still hold: "
                      "docs/python.md, 'Scale your states'", stacklevel=stacklevel)


def minibatch(x: torch.Tensor, y: torch.Tensor, batch_size: int | None, gen: torch.Generator):
    """The whole set when ``batch_size`` is None or covers it, else a random minibatch without replacement."""
    if batch_size is None or batch_size >= len(x):
        return x, y
    # drawn by the CPU generator ``gen`` on every device, so a seed picks the same rows everywhere
    ix = torch.randperm(len(x), generator=gen, device="cpu")[:batch_size].to(x.device)
    # index_select is the same gather as x[ix], and faster (docs/speed.md, "Why the fast paths")
    return x.index_select(0, ix), y.index_select(0, ix)


class GroupRows:
    """The rows each model trains on, padded to one ``(G, rows, n)`` stack, and how it draws minibatches
    (both group trainers: ``hnn.trainers.closed_form`` and ``hnn.trainers.vmap``). A model's padding repeats its first row at weight 0:
    a real state, so a model that is singular at a zero state (an LNN) sees none."""

    def __init__(self, xs, ys, batch_size, seeds, seed_offset: int):
        self.counts = [len(x) for x in xs]
        most = max(self.counts)
        self.x = torch.stack([torch.cat([x, x[:1].expand(most - len(x), -1)]) for x in xs])
        self.y = torch.stack([torch.cat([y, y[:1].expand(most - len(y), -1)]) for y in ys])
        self.batch_size = batch_size
        # CPU generators on every device: a seed draws the lone run's rows wherever the group trains
        self.gens = [torch.Generator("cpu").manual_seed(seed + seed_offset) for seed in seeds]
        sizes = [c if batch_size is None or batch_size >= c else batch_size for c in self.counts]
        self.size = max(sizes)
        # weight of each row in its model's mean: 1/(rows * width) for a drawn row, 0 for padding
        weight = torch.zeros(len(xs), self.size, dtype=self.x.dtype, device=self.x.device)
        for g, m in enumerate(sizes):
            weight[g, :m] = 1.0 / (m * self.x.shape[2])
        self.weight = weight
        self.full = all(m == c for m, c in zip(sizes, self.counts))
        self._models = torch.arange(len(xs), device=self.x.device)[:, None]

    def draw(self):
        """``(x, y)`` of this step, ``(G, size, n)`` each: the lone run's ``minibatch``
        of every model (its generator advances only when it draws)."""
        if self.full:
            return self.x[:, :self.size], self.y[:, :self.size], self.gens
        index = torch.zeros(len(self.gens), self.size, dtype=torch.long, device="cpu")
        for g, (gen, count) in enumerate(zip(self.gens, self.counts)):
            if self.batch_size >= count:
                index[g, :count] = torch.arange(count, device="cpu")
            else:
                index[g] = torch.randperm(count, generator=gen, device="cpu")[:self.batch_size]
        index = index.to(self.x.device)
        return self.x[self._models, index], self.y[self._models, index], self.gens

    def drawn(self) -> list[int]:
        """How many real rows each model draws a step."""
        return [c if self.batch_size is None or self.batch_size >= c else self.batch_size for c in self.counts]

    def noisy(self, xb: torch.Tensor, gens, input_noise: float) -> torch.Tensor:
        """``xb`` ``(G, size, n)`` plus each model's input noise, drawn from its generator as its lone run
        draws it (``hnn.train``): the real rows' noise only, in the CPU generator's order."""
        if not input_noise:
            return xb
        n = xb.shape[-1]
        noise = torch.stack([torch.cat([torch.randn((c, n), generator=gen, device="cpu"),
                                        torch.zeros(xb.shape[1] - c, n, device="cpu")])
                             for gen, c in zip(gens, self.drawn())])
        return xb + input_noise * noise.to(xb)

    def loss(self, prediction: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
        """Each model's mean squared error over its own rows, ``(G,)``."""
        return ((y - prediction).pow(2).sum(-1) * self.weight).sum(-1)
