"""Fixed-seed regression of the spring task against the paper's published numbers (seed 0, default flags).

Training amplifies the last bits of every float sum, and those depend on the thread count and on
the CPU kernels torch picks (AVX-512 or AVX2), so the test pins one thread and every threshold is
set from the spread measured by ``python analysis/regression_spread.py --kernels default avx2``
(seeds 0-4 x threads 1, 2 x AVX-512, AVX2 kernels: 20 trainings of each model), with its margin.
"""
import pytest
import torch

import hnn
from hnn.paper import PAPER


@pytest.fixture(scope="module")
def spring_runs(tmp_path_factory):
    out = tmp_path_factory.mktemp("runs")
    trainer = hnn.load_task("spring", "train")
    threads = torch.get_num_threads()
    torch.set_num_threads(1)            # one thread: the same kernels and sums at any OMP_NUM_THREADS
    try:
        return {label: trainer.main(["--save_dir", str(out)] + (["--baseline"] if label == "baseline" else []))
                for label in ("baseline", "hnn")}
    finally:
        torch.set_num_threads(threads)


@pytest.fixture(scope="module")
def energy(spring_runs):
    models = {label: hnn.load_run(run)[0] for label, run in spring_runs.items()}
    spring = hnn.load_task("spring")
    return {protocol: hnn.evaluate_energy(spring, models, hnn.get_protocol("spring", protocol))
            for protocol in ("paper", "corrected")}


def test_spring_losses_match_the_paper(spring_runs):
    # measured: every loss of the 20 trainings lies within 11% of the paper's (seed 2's test
    # losses are the farthest; seed 0's within 0.5%); 15% leaves room for other kernels
    for label, run in spring_runs.items():
        _, _, metrics = hnn.load_run(run)
        for key in ("train_loss", "test_loss"):
            assert metrics[key] == pytest.approx(PAPER["spring"][key][label][0], rel=0.15), (label, key)


def test_spring_hnn_conserves_energy_far_better_than_the_baseline(energy):
    # measured baseline / HNN energy-MSE ratios over the 20 trainings: paper protocol 179x-1985x,
    # corrected protocol 35x-590x (seed 0: 364x-700x and 83x-159x); the thresholds sit 3.5x
    # below the smallest ratio seen
    for protocol, least in (("paper", 50), ("corrected", 10)):
        r = energy[protocol]
        assert r["hnn"]["mse"] * least <= r["baseline"]["mse"], (protocol, r["hnn"]["mse"], r["baseline"]["mse"])


def test_spring_energy_mse_near_the_paper(energy):
    # the paper's protocol lands within a factor of 3 of the published numbers (measured over the
    # 20 trainings: baseline 0.8x-1.4x, HNN 0.3x-1.9x of the paper's)
    r = energy["paper"]
    for label in ("baseline", "hnn"):
        paper = PAPER["spring"]["energy_mse"][label][0]
        assert paper / 3 < r[label]["mse"] < paper * 3, (label, r[label]["mse"], paper)
