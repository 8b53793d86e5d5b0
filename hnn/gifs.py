"""Animated GIFs of frame sequences, side by side: what a pixel model sees and predicts.

    write_gif({"truth": pixels, "hnn": decoded}, "truth-vs-hnn.gif")   # each (T, 2 side^2)
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .io import atomic_write


def _to_uint8(pixels: np.ndarray, side: int, scale: int) -> np.ndarray:
    """The first frame of each pair ``(T, 2 side^2)`` as ``(T, side*scale, side*scale)`` uint8 (0..0.5 -> 0..255)."""
    frames = np.asarray(pixels)[:, :side * side].reshape(-1, side, side)
    frames = np.clip(frames * 2.0, 0.0, 1.0) * 255
    return np.kron(frames, np.ones((scale, scale))).astype(np.uint8)


def write_gif(panels: dict, path, side: int = 28, scale: int = 4, ms_per_frame: int = 50) -> Path:
    """An animated GIF of panels side by side: ``{title: pixels (T, 2 side^2)}``, all of the same T.

    Each row holds a pair of ``side x side`` frames with values in [0, 0.5]; the first of each
    pair is shown, ``scale`` times enlarged, panels divided by a white gap. Written atomically.
    """
    import imageio.v3 as iio

    lengths = {len(v) for v in panels.values()}
    if len(lengths) != 1:
        raise ValueError(f"all panels need the same number of frames, got {lengths}")
    strips = [_to_uint8(v, side, scale) for v in panels.values()]
    gap = np.full((strips[0].shape[0], side * scale, 4), 255, dtype=np.uint8)   # a white divider
    movie = np.concatenate([x for s in strips for x in (s, gap)][:-1], axis=2)
    path = Path(path)
    atomic_write(path, lambda tmp: iio.imwrite(tmp, movie, extension=".gif", duration=ms_per_frame, loop=0))
    return path
