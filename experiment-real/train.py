"""Train the baseline or the HNN on task 3, the real pendulum (the original's flags and defaults).

    python experiment-real/train.py --verbose              # HNN
    python experiment-real/train.py --verbose --baseline   # baseline

Trains on the Schmidt & Lipson (2009) measurements that ship beside this file (DATA.md), or on
another copy (real_pend_h_1.txt or invar_datasets.zip) in --data_dir DIR or $HNN_DATA_DIR. Weight decay 1e-5 is the original
code's hard-coded value (the paper says 1e-4); training is full batch (445 rows).
"""
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import hnn
from hnn.settings import setting

HERE = Path(__file__).resolve().parent


@dataclass
class Config(hnn.RunConfig):
    """Task 3: the real pendulum (Schmidt & Lipson 2009 measurements)."""
    name: str = "real"
    weight_decay: float = 1e-5
    save_dir: str = str(HERE)
    data_dir: str | None = setting(None, "folder holding real_pend_h_1.txt or invar_datasets.zip; default: "
                                         "$HNN_DATA_DIR, else the copy shipped in experiment-real/", parse=str)
    split: str = setting("original", "original: the HNN paper's forward differences and split; dhnn: the D-HNN "
                                     "paper's central differences and split of the same file (Sosanya & Greydanus "
                                     "2022)", choices=("original", "dhnn"))
    DATASET_FIELDS: ClassVar[tuple[str, ...]] = ("data_dir", "split")

    def dataset(self) -> dict:
        return hnn.load_task("real").get_dataset(data_dir=self.data_dir, split=self.split)


def main(argv=None):
    """Train one model, or reuse the complete run of these settings (--force retrains); returns its run folder."""
    return hnn.command.train(Config, argv)


if __name__ == "__main__":
    hnn.command.run_main(main)
