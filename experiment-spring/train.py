"""Train the baseline or the HNN on task 1, the ideal mass-spring (the original's flags and defaults).

    python experiment-spring/train.py --verbose              # HNN
    python experiment-spring/train.py --verbose --baseline   # baseline
"""
from dataclasses import dataclass
from pathlib import Path

import hnn

HERE = Path(__file__).resolve().parent


@dataclass
class Config(hnn.RunConfig):
    """Task 1: the ideal mass-spring, H = q^2 + p^2."""
    name: str = "spring"
    save_dir: str = str(HERE)

    def dataset(self) -> dict:
        return hnn.load_task("spring").get_dataset(seed=self.seed)


def main(argv=None):
    """Train one model, or reuse the complete run of these settings (--force retrains); returns its run folder."""
    return hnn.command.train(Config, argv)


if __name__ == "__main__":
    hnn.command.run_main(main)
