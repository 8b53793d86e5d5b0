"""Where a sampled layer's neurons come from (Rahma, Datar & Dietrich 2024, after Bolager et al. 2023).

- ``swim``: each neuron from a pair of data points (x_a, x_b): w = 2 s (x_b - x_a) / |x_b - x_a|^2,
  b = -w . x_a - s with s = atanh(1/2), so the neuron reads -1/2 at x_a and +1/2 at x_b: its steep part
  spans the pair. Pairs are drawn uniformly among candidate pairs, or, given function values at the
  points, with probability proportional to |change of the values| / distance (where the function
  changes fastest: SWIM proper; uniform pairs are their U-SWIM).
- ``elm``: an extreme learning machine's draw: w ~ N(0, I), b uniform over the data's range.

Every draw comes from ``numpy.random.default_rng(seed)``: a fit's seed decides its neurons. Arrays are
float64 numpy ``(width, in_dim)`` weights and ``(width,)`` biases.
"""
from __future__ import annotations

import math

import numpy as np

SPREAD = math.atanh(0.5)        # the neuron's value at the pair's ends: tanh(-/+ SPREAD) = -/+ 1/2
MIN_DISTANCE = 1e-10            # pairs of (numerically) one point carry no direction: never drawn


def _candidate_pairs(rows: int, width: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Index pairs ``(a, b)``, a != b, at least ``2 * width`` of them and at least one per row."""
    count = max(rows, 2 * width)
    a = rng.integers(0, rows, size=count)
    b = (a + rng.integers(1, rows, size=count)) % rows      # never a itself
    return a, b


def swim(x: np.ndarray, width: int, rng: np.random.Generator, values: np.ndarray | None = None):
    """``(weight (width, in_dim), bias (width,))`` of ``width`` neurons from pairs of the rows of ``x``
    ``(rows, in_dim)``: uniform pairs, or with ``values`` ``(rows,)`` or ``(rows, k)`` pairs where they
    change fastest. Distinct pairs unless fewer candidates than ``width`` can be told apart."""
    x = np.asarray(x, dtype=np.float64)
    if x.ndim != 2 or len(x) < 2:
        raise ValueError(f"SWIM draws neurons from pairs of data points: it needs at least 2 rows, got {x.shape}")
    a, b = _candidate_pairs(len(x), width, rng)
    direction = x[b] - x[a]
    distance = np.linalg.norm(direction, axis=1)
    usable = distance > MIN_DISTANCE
    if not usable.any():
        raise ValueError("every pair of data points drawn for SWIM is the same point; the states do not vary")
    if values is None:
        weight = usable.astype(np.float64)
    else:
        v = np.asarray(values, dtype=np.float64).reshape(len(x), -1)
        change = np.abs(v[b] - v[a]).max(axis=1)
        weight = np.where(usable, change / np.maximum(distance, MIN_DISTANCE), 0.0)
        if not weight.sum() > 0:        # a constant function: every direction is as good as another
            weight = usable.astype(np.float64)
    chosen = rng.choice(len(a), size=width, replace=np.count_nonzero(weight) < width, p=weight / weight.sum())
    d, a = direction[chosen], x[a[chosen]]
    w = 2 * SPREAD * d / (distance[chosen] ** 2)[:, None]
    return w, -(w * a).sum(axis=1) - SPREAD


def elm(x: np.ndarray, width: int, rng: np.random.Generator, values: np.ndarray | None = None):
    """``(weight (width, in_dim), bias (width,))``: w ~ N(0, I), b ~ U[min x, max x] over every entry of ``x``;
    ``values`` (a sampler's signature, ``swim``'s): unread, an ELM draws without looking at the function."""
    x = np.asarray(x, dtype=np.float64)
    low, high = float(x.min()), float(x.max())
    weight = rng.normal(size=(width, x.shape[1]))
    return weight, rng.uniform(low, high, size=width)
