"""Train the baseline or the HNN on task 2, the ideal pendulum (the original's flags and defaults).

    python experiment-pend/train.py --verbose              # HNN
    python experiment-pend/train.py --verbose --baseline   # baseline
"""
from pathlib import Path

import hnn

HERE = Path(__file__).resolve().parent


def parse_args(argv=None):
    return hnn.cli.make_parser("Task 2: the ideal pendulum, H = 3(1 - cos q) + p^2", name="pend", input_dim=2,
                               weight_decay=1e-4, save_dir=str(HERE)).parse_args(argv)


def dataset(args) -> dict:
    """The dataset a run with these flags trains on (evaluation rebuilds it from a run's saved args)."""
    return hnn.load_task("pend").get_dataset(seed=args.seed)


def main(argv=None):
    """Train one model; returns its run folder (checkpoint, args.json, metrics.json)."""
    args = parse_args(argv)
    return hnn.run_experiment(args, lambda: dataset(args))


if __name__ == "__main__":
    hnn.cli.run_main(main)
