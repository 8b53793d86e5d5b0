"""Train the baseline or the HNN on task 2, the ideal pendulum (the original's flags and defaults).

    python experiment-pend/train.py --verbose              # HNN
    python experiment-pend/train.py --verbose --baseline   # baseline
"""
from dataclasses import dataclass
from pathlib import Path

import hnn

HERE = Path(__file__).resolve().parent


@dataclass
class Config(hnn.RunConfig):
    """Task 2: the ideal pendulum, H = 3(1 - cos q) + p^2."""
    name: str = "pend"
    save_dir: str = str(HERE)

    def dataset(self) -> dict:
        return hnn.load_task("pend").get_dataset(seed=self.seed)


def main(argv=None):
    """Train one model, or reuse the complete run of these settings (--force retrains); returns its run folder."""
    return hnn.command.train(Config, argv)


if __name__ == "__main__":
    hnn.command.run_main(main)
