"""Fixed-seed regression against the paper's published numbers (seed 0, default flags)."""
import pytest

import hnn

# Train and test losses, from the original README (../shared/reference, section 10)
PAPER_LOSSES = {
    "baseline": {"train_loss": 3.7134e-02, "test_loss": 3.6656e-02},
    "hnn": {"train_loss": 3.6933e-02, "test_loss": 3.5928e-02},
}


@pytest.fixture(scope="module")
def spring_runs(tmp_path_factory):
    out = tmp_path_factory.mktemp("runs")
    trainer = hnn.load_task("spring", "train")
    return {label: trainer.main(["--save_dir", str(out)] + (["--baseline"] if label == "baseline" else []))
            for label in ("baseline", "hnn")}


def test_spring_losses_match_the_paper(spring_runs):
    for label, run in spring_runs.items():
        _, _, metrics = hnn.load_run(run)
        for key, paper in PAPER_LOSSES[label].items():
            assert metrics[key] == pytest.approx(paper, rel=0.10), (label, key)


def test_spring_hnn_conserves_energy_100x_better_than_the_baseline(spring_runs):
    models = {label: hnn.load_run(run)[0] for label, run in spring_runs.items()}
    spring = hnn.load_task("spring")
    for protocol in ("paper", "corrected"):
        r = hnn.evaluate_energy(spring, models, hnn.get_protocol("spring", protocol))
        assert r["hnn"]["mse"] * 100 <= r["baseline"]["mse"], (protocol, r["hnn"]["mse"], r["baseline"]["mse"])
    # the paper's protocol lands within a factor of 3 of the published numbers
    r = hnn.evaluate_energy(spring, models, hnn.get_protocol("spring", "paper"))
    assert 1.7077e-01 / 3 < r["baseline"]["mse"] < 1.7077e-01 * 3
    assert 3.8416e-04 / 3 < r["hnn"]["mse"] < 3.8416e-04 * 3
