import os

import pytest
import torch

import hnn

# the analysis package (hnn_analysis) is this checkout's analysis/ folder, whether or not the
# install maps it, so its tests import it by name like any package
hnn.tasks.import_analysis()

# the real-pendulum measurements ship with the task; a copy named by the user's environment
# must not change what the tests read
os.environ.pop("HNN_DATA_DIR", None)


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
