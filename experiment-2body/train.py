"""Train the baseline or the HNN on task 4, two bodies under gravity (the original's flags and defaults).

    python experiment-2body/train.py --verbose              # HNN
    python experiment-2body/train.py --verbose --baseline   # baseline

The dataset (1000 orbits, 50000 rows) is generated once per seed and cached as an .npz in
--save_dir. Weight decay 0 is the original's hard-coded value.
"""
from pathlib import Path

import hnn

HERE = Path(__file__).resolve().parent


def parse_args(argv=None):
    parser = hnn.cli.make_parser("Task 4: two bodies under Newtonian gravity (G = 1, unit masses)", name="2body",
                                 input_dim=8, weight_decay=0.0, total_steps=10000, batch_size=200,
                                 save_dir=str(HERE))
    parser.add_argument("--input_noise", type=hnn.cli.nonnegative_float, default=0.0,
                        help="std of Gaussian noise added to each training batch's inputs x (the original "
                             "declared it type=int, so only whole numbers parsed, and added the noise to the "
                             "predicted derivatives instead)")
    hnn.nbody.add_dataset_flags(parser)
    return parser.parse_args(argv)


def dataset(args) -> dict:
    """The dataset a run with these flags trains on (evaluation rebuilds it from a run's saved args)."""
    return hnn.load_task("2body").get_dataset(seed=args.seed, save_dir=args.save_dir,
                                           min_separation=args.min_separation)


def main(argv=None):
    """Train one model; returns its run folder (checkpoint, args.json, metrics.json)."""
    args = parse_args(argv)
    return hnn.run_experiment(args, lambda: dataset(args))


if __name__ == "__main__":
    hnn.cli.run_main(main)
