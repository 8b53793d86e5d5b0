"""Train the baseline or the HNN on the ideal mass-spring, H = q^2 + p^2 (the original's flags and defaults).

    python experiment-spring/train.py --verbose              # HNN
    python experiment-spring/train.py --verbose --baseline   # baseline
"""
from pathlib import Path

import hnn

HERE = Path(__file__).resolve().parent


def main(argv=None):
    parser = hnn.cli.make_parser("Task 1: the ideal mass-spring, H = q^2 + p^2", name="spring", input_dim=2, weight_decay=1e-4,
                                 save_dir=str(HERE))
    args = parser.parse_args(argv)
    data = hnn.load_task("spring")
    return hnn.run_experiment(args, data.get_dataset(seed=args.seed))


if __name__ == "__main__":
    main()
