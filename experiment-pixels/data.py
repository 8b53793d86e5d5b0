"""Task 5, the pendulum seen only through pixels: frames rendered by gymnasium's ``Pendulum-v1``.

The system: gym's pendulum (g = 10, m = l = 1, a frame every ``DT`` = 0.05 s, zero torque) in
the paper's canonical coordinates x = [q, p], q = the angle from the downward vertical (rad),
p = 0.25 x the angular velocity (rad/s). Its equation of motion is q'' = -(3g / 2l) sin q =
-15 sin q, so H = 3.75 (1 - cos q) + 2 p^2 is conserved (gym steps it with semi-implicit Euler,
which keeps H within a bounded wobble). The paper's energy is its half with the constant fitted
to the data, 1.9 (1 - cos q) + p^2.

What a model sees: 28x28 frames of the rod alone (the red channel minus the green one removes
the white background, the black axle and the grey torque arrow), cropped around the pivot in
units of the frame size, so any render size gives the same picture, and downsampled with PIL's
bilinear filter (what the original's removed ``scipy.misc.imresize`` called).

    data = get_dataset(seed=0)      # rendered once (~1 min), then cached in a 17 MB .npz
    data["pixels"]                  # (16000, 1568) float32: two adjacent frames per row
    data["next_pixels"]             # the pair one frame later

gymnasium and pygame are imported only here, when frames are rendered.
"""
from __future__ import annotations

import contextlib
import multiprocessing
import os
import sys
from pathlib import Path

import numpy as np
import torch
from tqdm.auto import tqdm

from hnn.cache import get_cached_dataset

HERE = Path(__file__).resolve().parent
NAME = "pixels"
ENV_NAME = "Pendulum-v1"
DT = 0.05                      # seconds per frame (gym's pendulum time step)
OMEGA2 = 15.0                  # 3 g / (2 l): q'' = -OMEGA2 sin q
MOMENTUM_SCALE = 0.25          # p = 0.25 q': the original's scale, which makes H ~ PE + KE with equal weights
ENERGY_K = 1.9                 # the paper's energy 1.9 (1 - cos q) + p^2 ("k fit to the data")
SIDE = 28
# The crop window around the pivot, in units of the frame size: rows from 0.06 above the pivot
# to 0.28 below it, columns 0.17 either side. On the 1000-pixel render the original assumed,
# this is exactly its rows 440:-220, columns 330:-330; on gym's 500-pixel render, 220:-110, 165:-165.
CROP_ABOVE, CROP_BELOW, CROP_HALF_WIDTH = 0.06, 0.28, 0.17
DEFAULTS = {"trials": 200, "timesteps": 103, "side": SIDE, "min_angle": 0.0, "max_angle": float(np.pi / 6),
            "test_split": 0.2, "render_size": 500}
DATASET_VERSION = 1


def hamiltonian(x: torch.Tensor) -> torch.Tensor:
    """The paper's pixel-pendulum energy 1.9 (1 - cos q) + p^2 of ``x = [q, p]`` ``(batch, 2)``; ``(batch,)``."""
    q, p = x[..., 0], x[..., 1]
    return ENERGY_K * (1 - torch.cos(q)) + p ** 2


def true_hamiltonian(x: torch.Tensor) -> torch.Tensor:
    """The exactly conserved energy of the continuous pendulum in these coordinates, scaled like the
    paper's: (OMEGA2 / 8)(1 - cos q) + p^2 = 1.875 (1 - cos q) + p^2; ``(batch,)``."""
    q, p = x[..., 0], x[..., 1]
    return OMEGA2 * MOMENTUM_SCALE ** 2 * 2 * (1 - torch.cos(q)) + p ** 2


def dynamics(x: torch.Tensor) -> torch.Tensor:
    """True dx/dt per second, ``(batch, 2)``: dq/dt = p / 0.25, dp/dt = -0.25 x 15 sin q."""
    q, p = x[..., 0], x[..., 1]
    return torch.stack([p / MOMENTUM_SCALE, -MOMENTUM_SCALE * OMEGA2 * torch.sin(q)], dim=-1)


def canonical(gym_state) -> np.ndarray:
    """gym's ``(theta, theta_dot)`` (theta = 0 upright) -> ``[q, p]`` (q = 0 hanging, wrapped to [-pi, pi))."""
    theta, theta_dot = np.asarray(gym_state, dtype=np.float64)[..., 0], np.asarray(gym_state)[..., 1]
    q = np.mod(theta, 2 * np.pi) - np.pi
    return np.stack([q, MOMENTUM_SCALE * theta_dot], axis=-1)


def crop_box(size: int) -> tuple[int, int, int, int]:
    """``(top, bottom, left, right)`` pixel bounds of the crop in a ``size``-pixel square render."""
    pivot = size // 2          # gym draws the pivot at the centre of the frame
    return (pivot - round(CROP_ABOVE * size), pivot + round(CROP_BELOW * size),
            pivot - round(CROP_HALF_WIDTH * size), pivot + round(CROP_HALF_WIDTH * size))


def preprocess(frame: np.ndarray, side: int = SIDE) -> np.ndarray:
    """One RGB render ``(S, S, 3)`` uint8 -> the rod alone, ``(side, side)`` uint8 (the original's 0..~127)."""
    from PIL import Image

    frame = np.asarray(frame)
    if frame.ndim != 3 or frame.shape[2] < 3 or frame.shape[0] != frame.shape[1] or frame.dtype != np.uint8:
        raise ValueError(f"expected a square uint8 RGB render (S, S, 3), got {frame.shape} {frame.dtype}")
    top, bottom, left, right = crop_box(frame.shape[0])
    window = frame[top:bottom, left:right]      # crop first: the channel arithmetic on 12% of the pixels
    rod = np.clip(window[..., 0].astype(np.int16) - window[..., 1], 0, 255).astype(np.uint8)
    return np.asarray(Image.fromarray(rod).resize((side, side), Image.BILINEAR))


def make_env(render_size: int = 500):
    """A headless ``Pendulum-v1`` that renders ``render_size``-pixel RGB frames."""
    os.environ.setdefault("SDL_VIDEODRIVER", "dummy")   # no display needed
    # SDL otherwise turns SIGINT/SIGTERM into quit events nobody reads: Ctrl-C and kill would be ignored
    os.environ.setdefault("SDL_NO_SIGNAL_HANDLERS", "1")
    os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
    try:
        import gymnasium
    except ImportError as err:
        raise ImportError("the pixel task renders frames with gymnasium and pygame: "
                          "pip install 'gymnasium[classic_control]' (or pip install -e '.[pixels]')") from err
    env = gymnasium.make(ENV_NAME, render_mode="rgb_array")
    env.unwrapped.screen_dim = int(render_size)
    return env


def sample_starts(seed: int, trials: int, min_angle: float = 0.0, max_angle: float = np.pi / 6) -> np.ndarray:
    """gym start states ``(trials, 2)`` = (theta, theta_dot): gym's own reset draws (theta ~ U[-pi, pi],
    theta_dot ~ U[-1, 1]) from ``reset(seed=seed)`` on, rejected until min_angle < |q| < max_angle."""
    if not 0 <= min_angle < max_angle:
        raise ValueError(f"need 0 <= min_angle < max_angle, got {min_angle}, {max_angle}")
    env = make_env()
    env.reset(seed=seed)
    starts = []
    for _ in range(trials):
        while True:
            state = np.array(env.unwrapped.state, dtype=np.float64)
            if min_angle < abs(canonical(state)[0]) < max_angle:
                break
            env.reset()
        starts.append(state)
        env.reset()
    env.close()
    return np.stack(starts)


@contextlib.contextmanager
def _images_loaded_once():
    """Inside: ``pygame.image.load`` reads each file once. gym's pendulum render reloads its
    torque-arrow PNG from disk on every frame (1.4 of its 3.3 ms here) and only reads it (it
    draws a scaled copy), so the frames are byte for byte the same."""
    import pygame

    real, loaded = pygame.image.load, {}

    def load(filename, *args):
        key = (os.fspath(filename) if isinstance(filename, (str, os.PathLike)) else id(filename), args)
        if key not in loaded:
            loaded[key] = real(filename, *args)
        return loaded[key]
    pygame.image.load = load
    try:
        yield
    finally:
        pygame.image.load = real


def _render_trial(job) -> tuple[np.ndarray, np.ndarray]:
    """Frames ``(timesteps, side, side)`` uint8 and gym states ``(timesteps + 1, 2)`` of one trial."""
    start, timesteps, side, render_size = job
    env = _worker_env(render_size)
    env.reset()
    env.unwrapped.state = np.array(start, dtype=np.float64)
    frames, states = [], [np.array(start, dtype=np.float64)]
    zero = np.zeros(1, dtype=np.float32)
    with _images_loaded_once():
        for _ in range(timesteps):
            frames.append(preprocess(env.render(), side))   # render the state first, then step (as the original)
            env.step(zero)
            states.append(np.array(env.unwrapped.state, dtype=np.float64))
    return np.stack(frames), np.stack(states)


_ENVS: dict = {}


def _worker_env(render_size: int):
    if render_size not in _ENVS:
        _ENVS[render_size] = make_env(render_size)
    return _ENVS[render_size]


def render_trials(starts: np.ndarray, timesteps: int, side: int = SIDE, render_size: int = 500,
                  workers: int | None = None, progress: bool | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Render zero-torque trials from gym start states ``(trials, 2)``.

    Returns frames ``(trials, timesteps, side, side)`` uint8 (frame i shows state i) and canonical
    states ``(trials, timesteps + 1, 2)`` float64. Rendering is pure CPU work in pygame, so
    ``workers`` processes (default: the cores) split the trials; the result does not depend on it.
    """
    workers = max(1, min(len(starts), workers or os.cpu_count() or 1))
    jobs = [(s, timesteps, side, render_size) for s in starts]
    if progress is None:
        progress = sys.stderr.isatty()
    bar = tqdm(total=len(jobs), desc=f"rendering {len(jobs)} trials x {timesteps} frames", disable=not progress,
               leave=False)
    if workers == 1:
        out = []
        for job in jobs:
            out.append(_render_trial(job))
            bar.update()
    else:
        # fork: the children inherit this module (loaded by path, so not importable by name)
        pool = multiprocessing.get_context("fork").Pool(workers)
        try:
            out = []
            for result in pool.imap(_render_trial, jobs, chunksize=4):
                out.append(result)
                bar.update()
            pool.close()
            pool.join()
        except BaseException:
            pool.terminate()
            raise
    bar.close()
    frames = np.stack([f for f, _ in out])
    states = canonical(np.stack([s for _, s in out]))
    return frames, states


def pair_rows(frames: np.ndarray, states: np.ndarray) -> dict:
    """The original's training rows from trials of ``T`` frames: ``T - 3`` per trial.

    Row k of a trial: ``pixels`` = frames (k+1, k+2) side by side (``2 side^2`` values in [0, 0.5]),
    ``next_pixels`` = frames (k+2, k+3), ``coords`` = the state one step after the second frame
    (k+3, the original's off-by-one, kept for its energy protocol), ``dcoords`` = its backward
    difference, and ``pair_coords`` = the state the second frame shows (k+2).
    """
    trials, T = frames.shape[:2]
    flat = frames.reshape(trials, T, -1)
    pairs = np.concatenate([flat[:, :-1], flat[:, 1:]], axis=-1).astype(np.float32) / np.float32(255)
    n = T - 3
    return {"pixels": pairs[:, 1:n + 1].reshape(trials * n, -1),
            "next_pixels": pairs[:, 2:n + 2].reshape(trials * n, -1),
            "coords": states[:, 3:n + 3].reshape(trials * n, 2),
            "dcoords": (states[:, 3:n + 3] - states[:, 2:n + 2]).reshape(trials * n, 2),
            "pair_coords": states[:, 2:n + 2].reshape(trials * n, 2)}


def sample_frames(seed: int = 0, trials: int = 200, timesteps: int = 103, side: int = SIDE, min_angle: float = 0.0,
                  max_angle: float = np.pi / 6, render_size: int = 500, workers: int | None = None) -> dict:
    """Frames ``(trials, timesteps, side, side)`` uint8 and canonical states ``(trials, timesteps + 1, 2)``."""
    starts = sample_starts(seed, trials, min_angle, max_angle)
    frames, states = render_trials(starts, timesteps, side, render_size, workers)
    return {"frames": frames, "states": states}


def get_dataset(seed: int = 0, save_dir=HERE, workers: int | None = None, **params) -> dict:
    """200 trials of 103 frames (|q0| < pi/6, zero torque), cached as uint8 frames in ``save_dir``.

    Returns float32 ``pixels``/``next_pixels`` ``(16000, 1568)``, float64 ``coords``, ``dcoords``,
    ``pair_coords`` ``(16000, 2)``, the same with a ``test_`` prefix for the first 20% of the
    trials (4000 rows), the raw ``frames``/``states`` and the cache file's name ``cache_key``.
    ``params`` override ``DEFAULTS``.
    """
    unknown = set(params) - set(DEFAULTS)
    if unknown:
        raise TypeError(f"unknown dataset params {sorted(unknown)}; known: {sorted(DEFAULTS)}")
    p = {**DEFAULTS, **params, "seed": seed, "version": DATASET_VERSION}
    if not 0 <= p["test_split"] < 1 or p["timesteps"] < 4 or p["trials"] < 1:
        raise ValueError(f"need 0 <= test_split < 1, timesteps >= 4 and trials >= 1; got {p}")
    raw = get_cached_dataset(save_dir, f"{NAME}-frames", p, lambda: sample_frames(
        seed, p["trials"], p["timesteps"], p["side"], p["min_angle"], p["max_angle"], p["render_size"], workers),
        describe=lambda d: f"{p['trials']} trials x {p['timesteps']} frames at {p['render_size']} px")
    num_test = int(p["test_split"] * p["trials"])
    test, train = (pair_rows(raw["frames"][s], raw["states"][s])
                   for s in (slice(None, num_test), slice(num_test, None)))
    data = {**train, **{f"test_{k}": v for k, v in test.items()}}
    data.update(frames=raw["frames"], states=raw["states"], dt=DT, params=p, cache_key=raw["cache_key"])
    return data
