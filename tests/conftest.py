import os
from pathlib import Path

import pytest
import torch

REPO = Path(__file__).resolve().parent.parent
# the real-pendulum measurements sit beside the checkout, never inside it
os.environ.setdefault("HNN_DATA_DIR", str(REPO.parent / "shared" / "data"))


@pytest.fixture(autouse=True)
def _seed():
    torch.manual_seed(0)


@pytest.fixture
def spring():
    import hnn
    return hnn.load_task("spring")


@pytest.fixture
def pend():
    import hnn
    return hnn.load_task("pend")
