"""Fixed-seed regression of the spring task against the paper's published numbers (seed 0, default flags).

Training amplifies the last bits of every float sum, and those depend on the thread count and on
the CPU kernels torch picks (AVX-512 or AVX2), so the test pins one thread and every threshold is
set from the spread measured by ``python analysis/paper/regression_spread.py --kernels default avx2``
(seeds 0-4 x threads 1, 2 x torch's AVX-512 and AVX2 kernels on an AVX-512 CPU: 20 trainings of
each model) and by the same command under ``ATEN_CPU_CAPABILITY=default`` (torch's scalar kernels, the
elementwise functions' last bits of a CPU without AVX2 or of another libm: seeds 0-2 at one thread),
with its margin. Seeds stand in for the last-bit changes of other machines: the thread count moved
seed 0's HNN energy MSE by 1.9x and the scalar kernels by 14x (0.66x the paper's -> 9.2x), the
widest of the 23 trainings, so the bands below hold that one with their margin.
"""
import pytest
import torch

import hnn
from hnn.tasks import PAPER


@pytest.fixture(scope="module")
def spring_runs(tmp_path_factory):
    out = tmp_path_factory.mktemp("runs")
    trainer = hnn.load_task("spring", "train")
    threads = torch.get_num_threads()
    torch.set_num_threads(1)            # one thread: the same kernels and sums at any OMP_NUM_THREADS
    try:
        return {kind: trainer.main(["--save_dir", str(out)] + (["--baseline"] if kind == "baseline" else []))
                for kind in ("baseline", "hnn")}
    finally:
        torch.set_num_threads(threads)


@pytest.fixture(scope="module")
def energy(spring_runs):
    models = {kind: hnn.load_run(run)[0] for kind, run in spring_runs.items()}
    spring = hnn.load_task("spring")
    return {protocol: hnn.evaluate_energy(spring, models, hnn.tasks.get_protocol("spring", protocol))
            for protocol in ("paper", "corrected")}


def test_spring_losses_match_the_paper(spring_runs):
    # measured: every loss of the 20 trainings lies within 12.3% of the paper's (seed 2's test
    # losses are the farthest; seed 0's all within 0.2%); 20% is 1.6x the worst seed
    for kind, run in spring_runs.items():
        _, _, metrics = hnn.load_run(run)
        for key in ("train_loss", "test_loss"):
            assert metrics[key] == pytest.approx(PAPER["spring"][key][kind][0], rel=0.20), (kind, key)


def test_spring_hnn_conserves_energy_far_better_than_the_baseline(energy):
    # measured baseline / HNN energy-MSE ratios over the 20 trainings: paper protocol 179x-1985x,
    # corrected protocol 35x-590x (seed 0: 364x-700x and 83x-159x); under torch's scalar kernels
    # seed 0 gave 49.7x and 11.3x (seeds 1, 2: 327x-649x, 44x-64x). The thresholds sit 3.5x below
    # the smallest ratio seen (they were 50 and 10, 3.5x below the 20 trainings' smallest)
    for protocol, least in (("paper", 14), ("corrected", 3)):
        r = energy[protocol]
        assert r["hnn"]["mse"] * least <= r["baseline"]["mse"], (protocol, r["hnn"]["mse"], r["baseline"]["mse"])


def test_spring_energy_mse_near_the_paper(energy):
    # measured over the 20 trainings, as a multiple of the paper's number: baseline 0.46x-3.59x,
    # HNN 0.38x-2.21x (seed 0: baseline 1.03x, HNN 0.66x at one thread and 1.25x at two); under
    # torch's scalar kernels seed 0's HNN gave 9.2x (baseline 1.03x; seeds 1, 2: HNN 0.99x-2.4x,
    # baseline 0.73x-3.5x). The band [1/6, 15] keeps 1.6x margin on the widest of them (it was
    # [1/6, 6], 1.7x over the 20 trainings)
    r = energy["paper"]
    for kind in ("baseline", "hnn"):
        paper = PAPER["spring"]["energy_mse"][kind][0]
        assert paper / 6 < r[kind]["mse"] < paper * 15, (kind, r[kind]["mse"], paper)
