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


# `pytest -m quick`: a first check in about a minute (tests/ and docs/testing.md: how long), the modules that hold
# the physics and the numbers to their truths (analytic solutions, conservation, orders, the paper's error bars,
# resuming to the same floats); the rest (sweeps, studies, commands end to end) is the full `pytest`
QUICK = {"test_metrics", "test_integrate", "test_symplectic", "test_dop853", "test_models", "test_model_interface",
         "test_training", "test_threads", "test_data", "test_real", "test_nbody", "test_specs", "test_kind_docs",
         "test_balance", "test_stability", "test_stability_warning", "test_tasks", "test_resume", "test_floor",
         "test_verdict_seeds", "test_docs_agree", "test_plan"}


def pytest_collection_modifyitems(config, items):
    for item in items:
        if item.module.__name__.rsplit(".", 1)[-1] in QUICK and item.get_closest_marker("slow") is None:
            item.add_marker(pytest.mark.quick)
