"""The map benchmark (analysis/benchmarks/maps.py) end to end on a tiny budget: the SympNets pendulum's
data (sympnets' [p, q] = [0, 1] is q = 1, p = 0 here, on its energy level), every model row, the medians
and the goals computed from the rows, and the page section that says them."""
import dataclasses
import json

import numpy as np
import pytest
import torch

from hnn_analysis.benchmarks import map_protocols as mp
from hnn_analysis.benchmarks import map_report, maps


def test_the_pendulum_protocols_data_are_sympnets_orbit(tmp_path):
    arrays = mp.data(mp.PENDULUM, tmp_path)
    pairs, test = arrays["pairs"], arrays["test"]
    assert pairs.shape == (40, 4) and test.shape == (1, 101, 2)
    torch.testing.assert_close(pairs[0, :2], torch.tensor([1.0, 0.0]))
    torch.testing.assert_close(pairs[1:, :2], pairs[:-1, 2:])               # consecutive states, one step apart
    torch.testing.assert_close(test[0, 0], pairs[-1, 2:])                   # the test starts where training ends
    energy = mp.pendulum_energy(test[0].double())
    assert float((energy - (-np.cos(1.0))).abs().max()) < 1e-6               # the true orbit keeps H = -cos 1


def test_a_tiny_benchmark_writes_every_row_its_medians_and_goals(tmp_path, monkeypatch):
    monkeypatch.setitem(mp.PROTOCOLS, "pendulum", dataclasses.replace(mp.PENDULUM, quick_steps=20))
    results = maps.main(["--quick", "--protocols", "pendulum", "--seeds", "2", "--repeats", "1",
                         "--floor-rounds", "3", "--out", str(tmp_path)])["pendulum"]
    labels = mp.labels(mp.PENDULUM)
    assert [r["label"] for r in results["rows"]] == labels * 2
    # the HNN rolled out two ways is one trained model per seed
    rows = {(r["label"], r["seed"]): r for r in results["rows"]}
    for seed in (0, 1):
        assert rows[("HNN + RK4", seed)]["train_loss"] == rows[("HNN + midpoint", seed)]["train_loss"]
    summary, goals = results["summary"], results["goals"]
    for label in labels:
        seconds = sorted(rows[(label, s)]["seconds_per_step"] for s in (0, 1))
        assert summary[label]["seconds_per_step"] == pytest.approx([sum(seconds) / 2, *seconds])
        assert goals[label]["cost_ratio"] == pytest.approx(summary[mp.REFERENCE]["seconds_per_step"][0]
                                                           / summary[label]["seconds_per_step"][0])
    for label in mp.PENDULUM.maps:
        g = goals[label]
        assert g["cost_met"] == (g["cost_ratio"] >= map_report.COST_GOAL)
        assert g["error_met"] == (g["error_ratio"] <= map_report.ERROR_GOAL)
    assert set(results["floors"]) == set(mp.PENDULUM.maps) | {mp.REFERENCE}
    text = (tmp_path / "maps-pendulum.md").read_text()
    assert "QUICK smoke run" in text and "| g_sympnet |" in text and "Goal (issue #72)" in text
    assert json.loads((tmp_path / "maps-pendulum.json").read_text())["meta"]["protocol"]["h"] == 0.1
