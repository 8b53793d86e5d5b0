"""Train the baseline or the HNN on task 3, the real pendulum (the original's flags and defaults).

    python experiment-real/train.py --verbose              # HNN
    python experiment-real/train.py --verbose --baseline   # baseline

Trains on the Schmidt & Lipson (2009) measurements that ship beside this file (DATA.md), or on
another copy (real_pend_h_1.txt or invar_datasets.zip) in --data_dir DIR or $HNN_DATA_DIR. Weight decay 1e-5 is the original
code's hard-coded value (the paper says 1e-4); training is full batch (445 rows).
"""
from pathlib import Path

import hnn

HERE = Path(__file__).resolve().parent


def parse_args(argv=None):
    parser = hnn.cli.make_parser("Task 3: the real pendulum (Schmidt & Lipson 2009 measurements)", name="real",
                                 input_dim=2, weight_decay=1e-5, save_dir=str(HERE))
    parser.add_argument("--data_dir", type=str, default=None,
                        help="folder holding real_pend_h_1.txt or invar_datasets.zip; "
                             "default: $HNN_DATA_DIR, else the copy shipped in experiment-real/")
    parser.add_argument("--split", choices=("original", "dhnn"), default="original",
                        help="original: the HNN paper's forward differences and split; dhnn: the D-HNN paper's "
                             "central differences and split of the same file (Sosanya & Greydanus 2022)")
    return parser.parse_args(argv)


def dataset(args) -> dict:
    """The dataset a run with these flags trains on (evaluation rebuilds it from a run's saved args)."""
    return hnn.load_task("real").get_dataset(data_dir=args.data_dir, split=getattr(args, "split", "original"))


def main(argv=None):
    """Train one model; returns its run folder (checkpoint, args.json, metrics.json)."""
    args = parse_args(argv)
    return hnn.run_experiment(args, lambda: dataset(args))


if __name__ == "__main__":
    hnn.cli.run_main(main)
