"""Train the baseline or the HNN on task 1, the ideal mass-spring (the original's flags and defaults).

    python experiment-spring/train.py --verbose              # HNN
    python experiment-spring/train.py --verbose --baseline   # baseline
"""
from pathlib import Path

import hnn

HERE = Path(__file__).resolve().parent


def parse_args(argv=None):
    return hnn.cli.make_parser("Task 1: the ideal mass-spring, H = q^2 + p^2", name="spring", input_dim=2,
                               weight_decay=1e-4, save_dir=str(HERE)).parse_args(argv)


def dataset(args) -> dict:
    """The dataset a run with these flags trains on (evaluation rebuilds it from a run's saved args)."""
    return hnn.load_task("spring").get_dataset(seed=args.seed)


def main(argv=None):
    """Train one model; returns its run folder (checkpoint, args.json, metrics.json)."""
    args = parse_args(argv)
    return hnn.run_experiment(args, lambda: dataset(args))


if __name__ == "__main__":
    hnn.cli.run_main(main)
