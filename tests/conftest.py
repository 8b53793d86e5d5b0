import os

import pytest
import torch

import hnn

# the real-pendulum measurements ship with the task; a copy named by the user's environment
# must not change what the tests read
os.environ.pop("HNN_DATA_DIR", None)


@pytest.fixture(autouse=True)
def _seed():
    torch.manual_seed(0)


@pytest.fixture
def spring():
    return hnn.load_task("spring")


@pytest.fixture
def pend():
    return hnn.load_task("pend")
