"""Train the baseline or the HNN on task 5, the pendulum seen through pixels (the original's flags and defaults).

    python experiment-pixels/train.py --verbose              # HNN (PixelHNN: autoencoder + HNN on the latent)
    python experiment-pixels/train.py --verbose --baseline   # baseline (the latent derivative predicted directly)

The frames are rendered once per seed with gymnasium (about a minute on 2 cores) and cached as
a small .npz in --save_dir. After training, the energy MSE is measured on a fresh trajectory
(both protocols, printed beside the paper's numbers) and GIFs are written into the run folder.
Weight decay 1e-5 is the original's hard-coded value.
"""
import functools
from pathlib import Path

import hnn
from hnn.cli import int_at_least, nonnegative_float

HERE = Path(__file__).resolve().parent
# the autoencoder + latent HNN of hnn.PixelHNN, fit on pairs of frames one frame apart
OBJECTIVE = hnn.PixelObjective(("pixels", "next_pixels", "test_pixels", "test_next_pixels"))


def parse_args(argv=None):
    parser = hnn.cli.make_parser("Task 5: a pendulum seen only through 28x28 gymnasium renders", name="pixels",
                                 input_dim=2 * 28 * 28, weight_decay=1e-5, total_steps=10000, batch_size=200,
                                 save_dir=str(HERE), rk4_help="step the latent by one RK4 step per frame "
                                 "instead of the paper's Euler step", state="input (two 28x28 frames side by side)")
    parser.add_argument("--latent_dim", type=int_at_least(2, even=True, why=" (z = [q, p])"), default=2,
                        help="width of the latent state z = [q, p]")
    parser.add_argument("--input_noise", type=nonnegative_float, default=0.0,
                        help="std of Gaussian noise added to the latent z before the latent field")
    parser.add_argument("--ae_nonlinearity", type=str, default="relu", choices=hnn.models.NONLINEARITIES,
                        help="activation of the autoencoder")
    parser.add_argument("--trials", type=int_at_least(5, why=" (the first 20% of them are the test set)"),
                        default=200, help="rendered trajectories (the first 20%% test)")
    parser.add_argument("--timesteps", type=int_at_least(4, why=" (each trajectory gives timesteps - 3 rows)"),
                        default=103, help="frames per trajectory (each gives timesteps - 3 rows)")
    parser.add_argument("--render_size", type=int_at_least(1), default=500,
                        help="side of gym's square render in pixels (the crop scales with it)")
    parser.add_argument("--render_workers", type=int_at_least(1), default=None, display_only=True,
                        help="processes that render frames (default: the cores); the frames do not depend on it")
    parser.add_argument("--no_eval", action="store_true", display_only=True,
                        help="skip the energy metric and the GIFs after training")
    args = parser.parse_args(argv)
    if args.model not in ("hnn", "baseline"):      # the latent field's kinds registered for pixels
        parser.error(f"--model {args.model}: the pixel task trains a latent hnn or baseline; pass one of those")
    return args


def dataset(args) -> dict:
    """The dataset a run with these flags trains on (evaluation rebuilds it from a run's saved args)."""
    return hnn.load_task("pixels").get_dataset(seed=args.seed, save_dir=args.save_dir, workers=args.render_workers,
                                               render_size=args.render_size, trials=args.trials,
                                               timesteps=args.timesteps)


def main(argv=None):
    """Train one model, then measure its energy MSE; returns its run folder."""
    args = parse_args(argv)
    data = functools.cache(lambda: dataset(args))      # rendered or read once, for training and evaluation
    directory = hnn.run_experiment(args, data, OBJECTIVE)
    if not args.no_eval:
        metric = hnn.load_task("pixels", "metric")
        metric.evaluate_pixel_run(directory, hnn.load_task("pixels"), data(), args.render_size, verbose=True)
    return directory


if __name__ == "__main__":
    hnn.cli.run_main(main)
