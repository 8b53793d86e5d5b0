"""The pixel pendulum's energy metric, its evaluation of a saved run, and its GIFs.

    result = evaluate_pixel_energy(system, models, hnn.tasks.get_protocol("pixels", "paper"), dataset)
    evaluate_pixel_run(directory, system, dataset)      # train.py: metrics.json, rollout.npz, GIFs
    evaluate(trained)                                    # reproduce.py: both protocols, both models

The energy metric, reconstructed from the paper's notebooks (the final one is lost; docs/original.md): a fresh
200-frame gym trajectory (seed 1, start angle in (pi/11, pi/10)); each model encodes its first
pixel pair, integrates its latent field, decodes every latent to pixels, encodes them again,
and maps the latents linearly to (q, p) (a map fitted per model on its training latents); the
energy 1.9 (1 - cos q) + p^2 of that path against the truth's, squared, mean ± the batch-means
standard error over 5 chunks of 40 frames. The original encoded the baseline's pixels with the
HNN's encoder; here every model uses its own. The two protocols (the paper's and a corrected
one) are ``PixelProtocol`` instances in this task's ``task.py``.
"""
from __future__ import annotations

import functools
import math
import warnings
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch

import hnn
from hnn.evaluation import check_integrator, describe_integrator, energy_bump, float64_copy, rollout_options
from hnn.integrators.integrate import rollout
from hnn.metrics import energy_mse
from hnn.io import atomic_write, write_json
from hnn.runs import load_run, run_dir

NAME = "pixels"


@dataclass(frozen=True)
class PixelProtocol:
    """How the pixel energy MSE is measured.

    Attributes:
        t_end, num_points: the latent path is sampled at ``linspace(0, t_end, num_points)``
            (time in frames); the paper used t_end = 196 for 200 frames, 0.98 of a frame apart.
        coords: ``'next_state'``: the truth at row k is the state one step after the pair's
            second frame (the original's off-by-one); ``'pair_state'``: the state that frame shows.
        prepend_truth: replace the model's first point by the true one (the paper's notebook).
        latent_map: ``'adam'``: a linear layer fitted by Adam (lr 1e-3, 4000 steps, batches of
            400, as the notebook); ``'lstsq'``: the exact least-squares affine map. The Adam
            map moves a weight by at most about 4, so it does not converge on a run whose
            latent p is small (std ~0.05: docs/original.md, "The pixel gap"); ``evaluate_pixel_energy``
            then warns and reports ``map_excess``.
        energy: ``'paper'``: 1.9 (1 - cos q) + p^2; ``'true'``: 1.875 (1 - cos q) + p^2, the
            conserved quantity of the pendulum gym simulates.
    """
    name: str
    t_end: float = 196.0
    num_points: int = 200
    rtol: float = 1e-3
    atol: float = 1e-6
    coords: str = "next_state"
    prepend_truth: bool = True
    latent_map: str = "adam"
    energy: str = "paper"
    seed: int = 1
    min_angle: float = math.pi / 11
    max_angle: float = math.pi / 10
    splits: int = 5
    # the latent integrator, as for hnn.EnergyProtocol: a name of hnn.SOLVERS and its options
    method: str = "solve_ivp"
    options: tuple = ()

    def __post_init__(self):
        check_integrator(self)

    def describe(self) -> str:
        return (f"{self.name}: one gym trajectory (seed {self.seed}, |q0| in ({self.min_angle:.3f}, "
                f"{self.max_angle:.3f})), {self.num_points} frames on t in [0, {self.t_end:g}] frames, "
                f"{describe_integrator(self)}, truth = {self.coords}, latent map {self.latent_map}, "
                f"energy = {self.energy}" + (", first point = truth" if self.prepend_truth else ""))


# the paper's add-energy demo in latent time (frames): flow 50, climb grad H for 1.8, flow 60;
# 500 points in all, spread in proportion to time
ADD_ENERGY = {"t_flow": 50.0, "t_bump": 1.8, "t_after": 60.0, "points": 450, "rtol": 1e-9, "atol": 1e-9}


def fit_latent_map(latents, coords, how: str = "adam", seed: int = 0):
    """An affine map latents ``(rows, 2)`` -> coords ``(rows, 2)``; returns ``z -> coords`` on float64 tensors."""
    z = torch.as_tensor(latents, dtype=torch.float64)
    c = torch.as_tensor(coords, dtype=torch.float64)
    if how == "lstsq":
        design = torch.cat([z, torch.ones(len(z), 1, dtype=z.dtype)], dim=1)
        sol = torch.linalg.lstsq(design, c).solution
        return lambda u: torch.cat([u.to(torch.float64), torch.ones(len(u), 1, dtype=torch.float64)], dim=1) @ sol
    if how != "adam":
        raise ValueError(f"latent_map must be 'adam' or 'lstsq', got {how!r}")
    gen = torch.Generator().manual_seed(seed)
    torch.manual_seed(seed)
    layer = torch.nn.Linear(z.shape[1], c.shape[1]).to(torch.float32)
    optim = torch.optim.Adam(layer.parameters(), lr=1e-3)
    z32, c32 = z.float(), c.float()
    for _ in range(4000):
        ix = torch.randint(len(z32), (400,), generator=gen)
        loss = (layer(z32[ix]) - c32[ix]).pow(2).mean()
        loss.backward()
        optim.step()
        optim.zero_grad(set_to_none=True)
    layer = layer.double().requires_grad_(False)
    return lambda u: layer(u.to(torch.float64))


# the Adam map's residual beyond which evaluate_pixel_energy warns, as a multiple of least squares
MAP_EXCESS_WARNING = 2.0


def map_excess(latents, coords, to_coords) -> float:
    """How much worse the map ``to_coords`` fits ``coords`` ``(rows, 2)`` from ``latents`` than the
    exact least-squares affine map: the largest ratio of the two mean squared residuals over the
    coordinates (1 for the least-squares map itself)."""
    z = torch.as_tensor(latents, dtype=torch.float64)
    c = torch.as_tensor(coords, dtype=torch.float64)
    best = fit_latent_map(z, c, "lstsq")
    with torch.no_grad():
        ratio = (to_coords(z) - c).pow(2).mean(0) / (best(z) - c).pow(2).mean(0).clamp_min(1e-300)
    return float(ratio.max())


def test_trajectory(system, protocol: PixelProtocol, render_size: int = 500) -> dict:
    """The evaluation trajectory as ``system.pair_rows`` gives it: ``pixels`` ``(num_points, 2 side^2)``,
    ``coords`` and ``pair_coords``. Rendered once per setting: both protocols share the frames."""
    return _render_trajectory(system, protocol.seed, protocol.num_points, protocol.min_angle, protocol.max_angle,
                              render_size)


@functools.lru_cache(maxsize=4)
def _render_trajectory(system, seed: int, num_points: int, min_angle: float, max_angle: float,
                       render_size: int) -> dict:
    raw = system.sample_frames(seed=seed, trials=1, timesteps=num_points + 3, min_angle=min_angle,
                               max_angle=max_angle, render_size=render_size, workers=1)
    return system.pair_rows(raw["frames"], raw["states"])


def latent_path(model, pixels, t_eval, protocol: PixelProtocol) -> torch.Tensor:
    """The latent path ``(len(t_eval), latent_dim)`` from the encoded first pixel pair ``pixels[:1]``,
    integrated as ``protocol`` says."""
    param = next(model.parameters())
    with torch.no_grad():
        z0 = model.encode(torch.as_tensor(pixels[:1], dtype=param.dtype, device=param.device))
    return rollout(model.time_derivative, z0, t_eval, **rollout_options(protocol))[0]


def evaluate_pixel_energy(system, models: dict, protocol: PixelProtocol, dataset: dict,
                          trajectory: dict | None = None) -> dict:
    """Energy MSE of each model in ``models`` (``{label: PixelHNN}``) under ``protocol``.

    ``dataset`` is the task's training set (for the latent maps); ``trajectory`` the output of
    ``test_trajectory`` (rendered when None). Returns ``{label: {mse, mse_se, energy, coords,
    decoded, map_excess}, 'truth': {energy, coords}, 'protocol': ...}``; ``map_excess`` is
    ``map_excess`` of the model's latent map (a warning names models above ``MAP_EXCESS_WARNING``:
    their energy MSE then measures the latent scale more than the dynamics).
    """
    trajectory = trajectory or test_trajectory(system, protocol)
    energy_fn = system.hamiltonian if protocol.energy == "paper" else system.true_hamiltonian
    true_coords = torch.as_tensor(trajectory["coords" if protocol.coords == "next_state" else "pair_coords"],
                                  dtype=torch.float64)
    e_true = energy_fn(true_coords)
    out = {"truth": {"energy": e_true.numpy(), "coords": true_coords.numpy(), "pixels": trajectory["pixels"]},
           "protocol": asdict(protocol)}
    t_eval = np.linspace(0.0, protocol.t_end, protocol.num_points)
    fit_coords = dataset["coords" if protocol.coords == "next_state" else "pair_coords"]
    for label, model in models.items():
        if protocol.name != "paper":
            model = float64_copy(model)     # the paper evaluated its float32 models as they are
        param = next(model.parameters())
        with torch.no_grad():
            latents = torch.cat([model.encode(torch.as_tensor(dataset["pixels"][i:i + 4000], dtype=param.dtype,
                                                              device=param.device)).cpu()
                                 for i in range(0, len(dataset["pixels"]), 4000)])
        to_coords = fit_latent_map(latents, fit_coords, protocol.latent_map)
        excess = map_excess(latents, fit_coords, to_coords)
        if excess > MAP_EXCESS_WARNING:
            warnings.warn(f"{protocol.name} protocol, {label}: the latent map fits the training coordinates "
                          f"{excess:.1f}x worse than least squares (latent std {[round(v, 3) for v in latents.std(0).tolist()]}); this "
                          f"energy MSE measures the latent scale as much as the dynamics; compare "
                          f"latent_map='lstsq' (docs/original.md, 'The pixel gap')", stacklevel=2)
        z = latent_path(model, trajectory["pixels"], t_eval, protocol)
        with torch.no_grad():
            decoded = model.decode(z.to(param.dtype))
            coords = to_coords(model.encode(decoded).cpu())     # its own encoder (the original used the HNN's)
        z, decoded = z.cpu(), decoded.cpu()         # the maps and energies are measured on the CPU
        if protocol.prepend_truth:
            coords[0] = true_coords[0]
        e_pred = energy_fn(coords)
        mse, se = energy_mse(e_true, e_pred, protocol.splits)
        out[label] = {"mse": mse, "mse_se": se, "energy": e_pred.numpy(), "coords": coords.numpy(),
                      "latents": z.double().numpy(), "decoded": decoded.numpy(), "map_excess": excess}
    return out


def _save_rollout(path, truth: np.ndarray, decoded: np.ndarray) -> None:
    """Both ``(T, 2 side^2)`` frame arrays, as float32, into an .npz archive at ``path``."""
    with open(path, "wb") as f:     # given a name, np.savez would append ".npz" to atomic_write's temp name
        np.savez_compressed(f, truth=truth.astype(np.float32), decoded=decoded.astype(np.float32))


def _sibling_run_name(args: dict) -> str:
    """The folder name of the run whose args are ``args`` with the model flipped (hnn <-> baseline)."""
    flipped = "hnn" if args["model"] == "baseline" else "baseline"
    return run_dir(hnn.tasks.task_config(NAME, {**args, "model": flipped})).name


def _protocols() -> dict:
    """``{name: PixelProtocol}`` of this task's ``task.py``."""
    return dict(hnn.task_spec(NAME).protocols)


def _measure(system, model, label: str, dataset: dict, render_size: int) -> tuple[dict, dict]:
    """``({energy_mse_<protocol>: [mse, ±]}, the paper protocol's result)`` of one model."""
    results = {name: evaluate_pixel_energy(system, {label: model}, protocol, dataset,
                                           test_trajectory(system, protocol, render_size))
               for name, protocol in _protocols().items()}
    energy = {f"energy_mse_{name}": [r[label]["mse"], r[label]["mse_se"]] for name, r in results.items()}
    return energy, results["paper"]


def _compare_gif(directory: Path, args: dict, label: str, truth: np.ndarray, decoded: np.ndarray) -> None:
    """truth | baseline | HNN beside the run folders, once both runs of this seed have a rollout."""
    other = directory.parent / _sibling_run_name(args)
    if not (other / "rollout.npz").exists():
        return
    with np.load(other / "rollout.npz") as f:
        pair = {label: decoded, "other": f["decoded"]}
    order = ("baseline", "hnn") if label == "baseline" else ("other", "hnn")
    panels = {"truth": truth, **{k: (pair[k] if k in pair else pair["other"]) for k in order}}
    hnn.gifs.write_gif(panels, directory.parent / f"{args['name']}-compare-seed{args['seed']}.gif")


def _add_energy_gif(directory: Path, model, z0) -> None:
    """The paper's add-energy demo from the latent ``z0``, decoded to ``add-energy.gif``."""
    bump = energy_bump(model, z0, **ADD_ENERGY)
    with torch.no_grad():
        param = next(model.parameters())
        frames = model.decode(torch.as_tensor(bump["x"], dtype=param.dtype, device=param.device)).cpu().numpy()
    hnn.gifs.write_gif({"add energy": frames[::2]}, directory / "add-energy.gif")


def _print_beside_paper(metrics: dict, label: str, directory: Path) -> None:
    paper = hnn.tasks.PAPER[NAME]
    print(f"{'metric':24s} {'paper':>24s} {'ours':>24s}")
    for key, title in (("train_loss", "train loss"), ("test_loss", "test loss"), ("energy_mse_paper", "energy MSE")):
        ours = metrics[key] if isinstance(metrics[key], list) else [metrics[key], metrics[key + "_se"]]
        ref = paper[key.replace("_paper", "")][label]
        print(f"{title + ' (' + label + ')':24s} {ref[0]:.4e} ± {ref[1]:.1e}  {ours[0]:.4e} ± {ours[1]:.1e}")
    print(f"energy MSE, corrected protocol: {metrics['energy_mse_corrected'][0]:.4e} ± "
          f"{metrics['energy_mse_corrected'][1]:.1e}; GIFs in {directory}")


def evaluate_pixel_run(directory, system, dataset: dict, render_size: int = 500, verbose: bool = True) -> dict:
    """After training: both energy protocols into the run's ``metrics.json``, the rollout's decoded
    frames into ``rollout.npz``, and GIFs (truth vs this model; truth vs baseline vs HNN once both
    runs of this seed exist in the same folder; the add-energy demo for an HNN). Returns the metrics."""
    directory = Path(directory)
    model, args, metrics = load_run(directory)
    label = args["model"]
    energy, result = _measure(system, model, label, dataset, render_size)
    metrics.update(energy)
    write_json(directory / "metrics.json", metrics)
    truth, decoded = result["truth"]["pixels"], result[label]["decoded"]
    atomic_write(directory / "rollout.npz", lambda tmp: _save_rollout(tmp, truth, decoded))
    hnn.gifs.write_gif({"truth": truth, label: decoded}, directory / f"truth-vs-{label}.gif")
    _compare_gif(directory, args, label, truth, decoded)
    if label == "hnn":
        _add_energy_gif(directory, model, result[label]["latents"][0])
    if verbose:
        _print_beside_paper(metrics, label, directory)
    return metrics


def evaluate(trained) -> dict:
    """``analysis/reproduce.py``'s evaluation (``TaskSpec.evaluate``): ``{protocol: result}`` of
    ``evaluate_pixel_energy`` for every model and protocol, on the dataset and render size the
    runs were trained with (``trained.dataset``, ``trained.args``)."""
    out = {}
    for name, protocol in _protocols().items():
        trajectory = test_trajectory(trained.system, protocol, trained.args["render_size"])
        result = evaluate_pixel_energy(trained.system, trained.models, protocol, trained.dataset, trajectory)
        result["description"] = protocol.describe()
        out[name] = result
    return out
