"""The pixel pendulum: gym renders -> 28x28 rod pictures -> PixelHNN, checked against physics and the original's layout."""
import contextlib
import json
import subprocess
import sys

import numpy as np
import pytest
import torch

import hnn
from hnn.models import MLPAutoencoder, PixelHNN
from hnn.objectives import pixel_loss

pytest.importorskip("gymnasium", reason="the pixel task renders with gymnasium: pip install -e '.[pixels]'")
pytest.importorskip("pygame", reason="gymnasium renders the pendulum with pygame: pip install -e '.[pixels]'")


@pytest.fixture(scope="module")
def system():
    return hnn.load_task("pixels")


@pytest.fixture(scope="module")
def metric():
    return hnn.load_task("pixels", "metric")


@pytest.fixture(scope="module")
def tiny(system, tmp_path_factory):
    """5 trials of 14 frames (1 test trial): rendered once for the module."""
    return system.get_dataset(seed=0, save_dir=tmp_path_factory.mktemp("pix"), workers=1, trials=5, timesteps=14)


def test_crop_matches_the_original_windows(system):
    # the original's hard-coded crop on its 1000-pixel render, and the same window at gym's 500 px
    assert system.crop_box(1000) == (440, 780, 330, 670)
    assert system.crop_box(500) == (220, 390, 165, 335)


def test_preprocess_keeps_only_the_rod(system):
    frame = np.full((500, 500, 3), 255, np.uint8)        # white background
    frame[240:260, 240:260] = 0                          # black axle
    frame[300:320, 200:210] = (128, 128, 128)            # grey torque arrow
    assert system.preprocess(frame).max() == 0
    frame[260:380, 239:262] = (204, 77, 77)              # the rod (gym draws it 23 px wide), hanging down
    out = system.preprocess(frame)
    assert out.shape == (28, 28) and out.dtype == np.uint8
    assert out.max() == 127                              # 204 - 77: the original's value range
    cols = np.nonzero(out.max(axis=0))[0]
    assert abs(cols.mean() - 13.5) < 1.5                 # centred under the pivot
    with pytest.raises(ValueError, match="square uint8 RGB"):
        system.preprocess(frame[:, :400])


def test_any_render_size_gives_the_same_picture(system):
    starts = system.sample_starts(3, 3)
    small, states_small = system.render_trials(starts, 6, render_size=250, workers=1)
    large, states_large = system.render_trials(starts, 6, render_size=500, workers=1)
    np.testing.assert_array_equal(states_small, states_large)
    a, b = small.astype(float), large.astype(float)
    # anti-aliased edges land on different sub-pixels at each size, so the pictures agree to a
    # few grey levels, not exactly (measured: mean |diff| 7% of the mean, correlation 0.996)
    assert np.corrcoef(a.ravel(), b.ravel())[0, 1] > 0.99
    assert np.abs(a - b).mean() < 0.15 * b.mean()
    # a render with the rod elsewhere is a different picture: the check above can fail
    other, _ = system.render_trials(system.sample_starts(4, 3), 6, render_size=250, workers=1)
    assert np.corrcoef(other.astype(float).ravel(), b.ravel())[0, 1] < 0.9


def test_preprocess_of_a_render_is_the_rod_channel_difference_cropped_and_resized(system):
    from PIL import Image

    env = system.make_env(500)
    env.reset(seed=1)
    frame = env.render()
    env.close()
    rod = np.clip(frame[..., 0].astype(np.int16) - frame[..., 1], 0, 255).astype(np.uint8)
    top, bottom, left, right = system.crop_box(500)
    expected = np.asarray(Image.fromarray(rod[top:bottom, left:right]).resize((28, 28), Image.BILINEAR))
    assert expected.max() > 100                  # the rod is in the picture
    np.testing.assert_array_equal(system.preprocess(frame), expected)


def test_the_arrow_image_loaded_once_gives_the_same_frames(system, monkeypatch):
    import pygame

    loads, real = [], pygame.image.load

    def counted(*args):
        loads.append(1)
        return real(*args)
    monkeypatch.setattr(pygame.image, "load", counted)
    job = (system.sample_starts(5, 1)[0], 5, 28, 250)
    frames, states = system._render_trial(job)
    assert len(loads) == 1                       # one load for the trial's 5 frames
    monkeypatch.setattr(system, "_images_loaded_once", contextlib.nullcontext)
    every_frame, states_again = system._render_trial(job)
    assert len(loads) == 1 + 5                   # gym's own way: a load per frame
    np.testing.assert_array_equal(frames, every_frame)
    np.testing.assert_array_equal(states, states_again)
    assert pygame.image.load is counted          # the real function is back after each trial


def test_starts_are_rejection_sampled_below_pi_over_6(system):
    starts = system.sample_starts(0, 20)
    q = system.canonical(starts)[:, 0]
    assert np.all(np.abs(q) < np.pi / 6) and np.all(np.abs(q) > 0)
    assert np.all(np.abs(starts[:, 1]) <= 1)             # gym's theta_dot ~ U[-1, 1]


def test_canonical_coordinates(system):
    q, p = system.canonical(np.array([[np.pi, 2.0], [np.pi + 0.3, 0.0], [0.0, 0.0]])).T
    np.testing.assert_allclose(q, [0.0, 0.3, -np.pi], atol=1e-12)    # theta = pi hangs down
    np.testing.assert_allclose(p, [0.5, 0.0, 0.0])                   # p = 0.25 theta_dot


def test_gym_states_obey_the_pendulum_equation(tiny, system):
    states = tiny["states"]                              # (trials, T + 1, 2) canonical
    q, p = states[..., 0], states[..., 1]
    qdot = p / system.MOMENTUM_SCALE
    # gym's semi-implicit Euler: qdot' = qdot - 15 sin q dt; q' = q + qdot' dt
    np.testing.assert_allclose(qdot[:, 1:], qdot[:, :-1] - system.OMEGA2 * np.sin(q[:, :-1]) * system.DT, atol=1e-5)
    np.testing.assert_allclose(q[:, 1:], q[:, :-1] + qdot[:, 1:] * system.DT, atol=1e-5)
    # that step is symplectic Euler: H itself wobbles by O(omega dt) ~ 20% here, but its modified
    # energy H - (dt/2) H_p H_q (per unit mass: v^2/2 + w^2 (1 - cos q) - (dt/2) v w^2 sin q) is
    # conserved to O(dt^2)
    w2, dt = system.OMEGA2, system.DT
    energy = qdot ** 2 / 2 + w2 * (1 - np.cos(q))
    modified = energy - dt / 2 * qdot * w2 * np.sin(q)
    spread = lambda e: np.ptp(e, axis=1) / e.mean(axis=1)   # noqa: E731
    assert np.all(spread(modified) < 0.02) and np.all(spread(modified) < spread(energy) / 5)
    np.testing.assert_allclose(system.true_hamiltonian(torch.as_tensor(states)).numpy(), energy / 8, rtol=1e-12)
    # and dynamics() is the symplectic gradient of the true H (times 2, the scale of the paper's energy)
    x = torch.as_tensor(states.reshape(-1, 2)).requires_grad_(True)
    dH = torch.autograd.grad(system.true_hamiltonian(x).sum(), x)[0]
    field = torch.stack([dH[:, 1], -dH[:, 0]], 1)
    torch.testing.assert_close(system.dynamics(x.detach()), 2 * field)


def test_pair_rows_follow_the_original_layout(system):
    T, side = 8, 2
    frames = np.arange(T, dtype=np.uint8)[None, :, None, None] * np.ones((1, T, side, side), np.uint8)
    states = np.arange(T + 1, dtype=float)[None, :, None] * np.ones((1, T + 1, 2))
    rows = system.pair_rows(frames, states)
    n = T - 3
    assert rows["pixels"].shape == (n, 2 * side * side)
    k = np.arange(n)
    np.testing.assert_allclose(rows["pixels"][:, 0] * 255, k + 1, rtol=1e-6)                # frames k+1, k+2
    np.testing.assert_allclose(rows["pixels"][:, -1] * 255, k + 2, rtol=1e-6)
    np.testing.assert_allclose(rows["next_pixels"][:, 0] * 255, k + 2, rtol=1e-6)           # one frame later
    np.testing.assert_allclose(rows["coords"][:, 0], k + 3)                                 # the off-by-one
    np.testing.assert_allclose(rows["pair_coords"][:, 0], k + 2)
    np.testing.assert_allclose(rows["dcoords"][:, 0], 1.0)


def test_dataset_shapes_split_and_determinism(tiny, system, tmp_path):
    assert tiny["pixels"].shape == (4 * 11, 1568) and tiny["test_pixels"].shape == (11, 1568)
    assert tiny["pixels"].dtype == np.float32 and 0 <= tiny["pixels"].min() and tiny["pixels"].max() <= 0.5
    assert tiny["frames"].dtype == np.uint8 and tiny["frames"].shape == (5, 14, 28, 28)
    assert tiny["pixels"].any(axis=1).all()              # every row shows the rod (no empty crops)
    # test = the first trial: its rows come from frames of trial 0
    np.testing.assert_allclose(tiny["test_pixels"][0, :784] * 255, tiny["frames"][0, 1].ravel(), rtol=1e-6)
    again = system.get_dataset(seed=0, save_dir=tmp_path, workers=2, trials=5, timesteps=14)
    np.testing.assert_array_equal(again["frames"], tiny["frames"])      # same seed, other worker count
    other = system.get_dataset(seed=1, save_dir=tmp_path, workers=1, trials=5, timesteps=14)
    assert not np.array_equal(other["frames"], tiny["frames"])
    assert len(list(tmp_path.glob("pixels-frames-*.npz"))) == 2
    with pytest.raises(TypeError, match="unknown dataset params"):
        system.get_dataset(seed=0, save_dir=tmp_path, trails=5)


def test_pixel_hnn_loss_is_the_papers_sum():
    torch.manual_seed(0)
    model = PixelHNN(8, 2, 16).double()
    x, x_next = torch.rand(5, 8, dtype=torch.float64), torch.rand(5, 8, dtype=torch.float64)
    z, z_next = model.encode(x), model.encode(x_next)
    ae = ((x - model.decode(z)) ** 2).mean(1)
    cc = (z[:, 1] - (z_next[:, 0] - z[:, 0])) ** 2       # the second latent is the per-frame change of the first
    dyn = ((z_next - z - model.time_derivative(z)) ** 2).mean(1)
    torch.testing.assert_close(pixel_loss(model, x, x_next), ae + cc + 0.1 * dyn)
    rk4 = hnn.integrators.rk4_step(model.time_derivative, z, 1.0)
    torch.testing.assert_close(pixel_loss(model, x, x_next, use_rk4=True), ae + cc + 0.1 * ((z_next - z - rk4) ** 2).mean(1))
    with pytest.raises(ValueError, match="same shape"):
        pixel_loss(model, x, x_next[:3])


def test_autoencoder_round_trip_on_a_tiny_dataset(tiny):
    torch.manual_seed(0)
    frames = torch.as_tensor(tiny["pixels"])              # 44 pairs from 4 trials
    ae = MLPAutoencoder(1568, 64, 2)
    optim = torch.optim.Adam(ae.parameters(), lr=1e-3)
    before = ((ae(frames) - frames) ** 2).mean().item()
    for _ in range(300):
        loss = ((ae(frames) - frames) ** 2).mean()
        loss.backward()
        optim.step()
        optim.zero_grad()
    after = loss.item()
    # frames of a swinging rod are a 1-D family: a 2-D latent reconstructs them far better
    # than their mean image does
    baseline = ((frames - frames.mean(0)) ** 2).mean().item()
    assert after < before / 10 and after < 0.5 * baseline, (before, after, baseline)
    assert ae.encode(frames).shape == (44, 2) and ae.decode(torch.zeros(3, 2)).shape == (3, 1568)
    with pytest.raises(ValueError, match="expected pixels"):
        ae.encode(frames[:, :100])


def test_latent_map_recovers_an_affine_map(metric):
    rng = np.random.RandomState(0)
    z = rng.randn(500, 2)
    A, b = np.array([[0.5, -1.0], [2.0, 0.3]]), np.array([0.1, -0.2])
    coords = z @ A + b
    fit = metric.fit_latent_map(z, coords, "lstsq")
    np.testing.assert_allclose(fit(torch.as_tensor(z)).numpy(), coords, atol=1e-10)
    adam = metric.fit_latent_map(z, coords, "adam")
    assert np.abs(adam(torch.as_tensor(z)).numpy() - coords).mean() < 0.05


def test_latent_map_excess_flags_an_adam_map_that_cannot_reach_small_latents(metric):
    # the paper protocol's Adam map moves a weight by at most ~4 (lr 1e-3, 4000 steps): latents
    # 50x smaller than the coordinates need weights of ~50, which it cannot reach
    rng = np.random.RandomState(0)
    z = rng.randn(2000, 2)
    coords = z @ np.array([[0.5, -1.0], [2.0, 0.3]]) + 0.1 * rng.randn(2000, 2)
    lstsq = metric.fit_latent_map(z, coords, "lstsq")
    assert metric.map_excess(z, coords, lstsq) == pytest.approx(1.0)
    assert metric.map_excess(z, coords, metric.fit_latent_map(z, coords, "adam")) < 1.5
    small = z / 50
    assert metric.map_excess(small, coords, metric.fit_latent_map(small, coords, "adam")) > 10


def test_train_script_end_to_end(tmp_path, system):
    trainer = hnn.load_task("pixels", "train")
    argv = ["--save_dir", str(tmp_path), "--trials", "5", "--timesteps", "14", "--total_steps", "40",
            "--batch_size", "16", "--render_workers", "1"]
    hnn_run = trainer.main(argv)
    base_run = trainer.main(argv + ["--baseline"])
    for run, label in ((hnn_run, "hnn"), (base_run, "baseline")):
        metrics = json.loads((run / "metrics.json").read_text())
        for key in ("train_loss", "test_loss"):
            assert np.isfinite(metrics[key]) and metrics[key] > 0
        for key in ("energy_mse_paper", "energy_mse_corrected"):
            assert np.all(np.isfinite(metrics[key]))
        assert len(metrics["history"]["train_loss"]) == 41
        assert metrics["history"]["train_loss"][-1] < metrics["history"]["train_loss"][0]
        assert (run / f"truth-vs-{label}.gif").stat().st_size > 1000
        model, args, _ = hnn.load_run(run)
        assert isinstance(model, PixelHNN) and model.baseline == (label == "baseline")
        assert args["kind"] == f"pixel-{label}" and args["dataset_cache_key"].startswith("pixels-frames-")
        assert (tmp_path / args["dataset_cache_key"]).is_file()          # the frames it trained on
    assert (hnn_run / "add-energy.gif").exists()
    assert (tmp_path / "pixels-compare-seed0.gif").exists()
    assert hnn.runs.find_run(hnn.cli.parse(trainer.Config, argv + ["--verbose", "--render_workers", "2"])) == hnn_run


def test_compare_gif_finds_the_sibling_run_when_the_name_holds_hnn(tmp_path, system, metric):
    # the baseline first: the HNN run, evaluated second, must find the baseline's rollout by its args
    trainer = hnn.load_task("pixels", "train")
    argv = ["--save_dir", str(tmp_path), "--name", "myhnn", "--trials", "5", "--timesteps", "14",
            "--total_steps", "5", "--batch_size", "16", "--render_workers", "1"]
    base_run = trainer.main(argv + ["--baseline"])
    assert not (tmp_path / "myhnn-compare-seed0.gif").exists()
    hnn_run = trainer.main(argv)
    assert base_run.name.startswith("myhnn-baseline-seed0-") and hnn_run.name.startswith("myhnn-hnn-seed0-")
    assert (tmp_path / "myhnn-compare-seed0.gif").stat().st_size > 1000
    with np.load(hnn_run / "rollout.npz") as f:
        assert f["truth"].dtype == np.float32 and f["truth"].shape == f["decoded"].shape
    args = {"name": "myhnn", "save_dir": "x", "seed": 2, "model": "hnn", "use_rk4": True}
    Config = hnn.load_task("pixels", "train").Config
    assert metric._sibling_run_name(args) == hnn.runs.run_dir(Config(**{**args, "model": "baseline"})).name
    assert metric._sibling_run_name({**args, "model": "baseline"}) == hnn.runs.run_dir(Config(**args)).name
    assert metric._sibling_run_name(args).startswith("myhnn-baseline-rk4-seed2-")


def test_add_energy_raises_the_learned_energy():
    torch.manual_seed(0)
    model = PixelHNN(8, 2, 16).double()
    bump = hnn.evaluation.energy_bump(model, [0.5, 0.0], t_flow=5.0, t_bump=0.5, t_after=5.0, points=60)
    H, stage = bump["H"], bump["stage"]
    # the symplectic phases keep the latent H; the gradient phase climbs it
    assert np.ptp(H[stage == 0]) < 1e-6 and np.ptp(H[stage == 2]) < 1e-6
    assert bump["H_after"] > bump["H_before"] + 1e-3
    np.testing.assert_allclose(bump["t"][-1], 10.5)
    with pytest.raises(ValueError, match="needs a model with a conserved H"):
        hnn.evaluation.energy_bump(PixelHNN(8, 2, 16, baseline=True), [0.5, 0.0])


def test_other_tasks_never_import_gymnasium():
    code = ("import sys, hnn; [hnn.load_task(t) for t in ('spring', 'pend', '2body')]; "
            "bad = [m for m in ('gymnasium', 'pygame') if m in sys.modules]; assert not bad, bad")
    subprocess.run([sys.executable, "-c", code], check=True)


def test_missing_gymnasium_says_how_to_install(system, monkeypatch):
    monkeypatch.setitem(sys.modules, "gymnasium", None)
    with pytest.raises(ImportError, match="pip install"):
        system.make_env()
