"""Train the baseline or the HNN on task 5, the pendulum seen through pixels (the original's flags and defaults).

    python experiment-pixels/train.py --verbose              # HNN (PixelHNN: autoencoder + HNN on the latent)
    python experiment-pixels/train.py --verbose --baseline   # baseline (the latent derivative predicted directly)

The frames are rendered once per seed with gymnasium (about a minute on 2 cores) and cached as
a small .npz in --save_dir. After training, the energy MSE is measured on a fresh trajectory
(both protocols, printed beside the paper's numbers) and GIFs are written into the run folder.
Weight decay 1e-5 is the original's hard-coded value.
"""
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import hnn
from hnn.settings import int_at_least, setting, task_setting

HERE = Path(__file__).resolve().parent


@dataclass
class Config(hnn.RunConfig):
    """Task 5: a pendulum seen only through 28x28 gymnasium renders."""
    name: str = "pixels"
    input_dim: int = 2 * 28 * 28
    weight_decay: float = 1e-5
    total_steps: int = 10000
    batch_size: int | None = 200
    save_dir: str = str(HERE)
    latent_dim: int = task_setting("latent_dim")
    input_noise: float = task_setting("input_noise", help="std of Gaussian noise added to the latent z before the "
                                                          "latent field")
    ae_nonlinearity: str = task_setting("ae_nonlinearity")
    trials: int = setting(200, "rendered trajectories (the first 20%% test)",
                          parse=int_at_least(5, why=" (the first 20% of them are the test set)"))
    timesteps: int = setting(103, "frames per trajectory (each gives timesteps - 3 rows)",
                             parse=int_at_least(4, why=" (each trajectory gives timesteps - 3 rows)"))
    render_size: int = setting(500, "side of gym's square render in pixels (the crop scales with it)",
                               parse=int_at_least(1))
    render_workers: int | None = setting(None, "processes that render frames (default: the cores); the frames do "
                                               "not depend on it", parse=int_at_least(1), display_only=True)
    no_eval: bool = setting(False, "skip the energy metric and the GIFs after training", display_only=True)

    STATE: ClassVar[str] = "input (two 28x28 frames side by side)"
    # the latent field's kinds registered for pixels (hnn.MODEL_KINDS "pixel-hnn", "pixel-baseline"): the
    # structured kinds are not wired into PixelHNN
    MODELS: ClassVar[tuple[str, ...]] = ("hnn", "baseline")
    KIND_PREFIX: ClassVar[str] = "pixel-"
    HELP: ClassVar[dict[str, str]] = {"use_rk4": "step the latent by one RK4 step per frame instead of the "
                                                 "paper's Euler step"}
    DATASET_FIELDS: ClassVar[tuple[str, ...]] = ("seed", "save_dir", "render_size", "trials", "timesteps")

    def dataset(self) -> dict:
        return hnn.load_task("pixels").get_dataset(seed=self.seed, save_dir=self.save_dir, workers=self.render_workers,
                                                   render_size=self.render_size, trials=self.trials,
                                                   timesteps=self.timesteps)

    def make_objective(self):
        # the autoencoder + latent HNN of hnn.PixelHNN, fit on pairs of frames one frame apart
        if self.objective != "derivative":
            raise ValueError(f"objective={self.objective!r}: the pixel task fits its autoencoder and latent field "
                             "on pairs of frames; use objective='derivative'")
        return hnn.objectives.PixelObjective(("pixels", "next_pixels", "test_pixels", "test_next_pixels"))

    def finish(self, directory, dataset: dict) -> None:
        """The energy MSE (both protocols) and the GIFs, unless ``no_eval``."""
        if not self.no_eval:
            metric = hnn.load_task("pixels", "metric")
            metric.evaluate_pixel_run(directory, hnn.load_task("pixels"), dataset, self.render_size, verbose=True)


def main(argv=None):
    """Train one model, then measure its energy MSE; returns its run folder."""
    return hnn.command.train(Config, argv)


if __name__ == "__main__":
    hnn.command.run_main(main)
