"""analysis/benchmarks/floor.py: the matrix products a training step performs, as the benchmark's floor counts them."""

import pytest
import torch

import hnn
from hnn.trainers.loop import adam_optimizer, optimizer_step
from hnn.training import l2_loss
from hnn_analysis.benchmarks import benchmark_report, floor, floor_job


def _baseline_step(rows=10, hidden=8):
    torch.manual_seed(0)
    model = hnn.build_model(2, hidden, baseline=True)
    x, y = torch.randn(rows, 2), torch.randn(rows, 2)
    optim = adam_optimizer(model, 1e-3, 0.0)
    loss = l2_loss(model.time_derivative)
    return lambda: optimizer_step(loss, x, y, optim)


def test_a_plain_mlp_step_performs_one_product_per_layer_forward_and_two_back_but_none_into_x():
    shapes = floor.products(_baseline_step())
    # forward: 3 layers; backward: a weight gradient for each, an input gradient for the upper two
    assert len(shapes) == 3 + 3 + 2
    assert shapes[:3] == [(10, 2, 8), (10, 8, 8), (10, 8, 2)]
    assert sorted(shapes[3:]) == sorted([(2, 10, 8), (10, 2, 8), (8, 10, 8), (10, 8, 8), (8, 10, 2)])


def test_the_hnn_step_performs_six_large_products_and_the_pixel_step_the_layers_count():
    d = hnn.load_task("spring").get_dataset(seed=0)
    spring = floor.products(floor_job.spring_step(d))
    assert floor.describe_products(spring) == "6 x 750x200x200 + 5 small"
    # the pixel step, counted from its layers: the encoder's 4 (on 400 rows: both frames) and the
    # decoder's 4 forward, each with a weight gradient and, but for the encoder's first, an input
    # gradient (15); the latent HNN's closed form, 4 forward and 8 backward (12); 8 + 15 + 12 = 35
    pixels = floor.products(floor_job.pixel_step())
    assert len(pixels) == 35
    assert pixels.count((400, 1568, 200)) == 1 and pixels.count((200, 200, 1568)) == 1


def test_compare_reports_the_ratio_of_medians_and_the_fastest_layout():
    step = _baseline_step(rows=64, hidden=32)
    shapes = floor.products(step)
    result = floor.compare(step, shapes, rounds=5, warmup=2)
    assert result["products"] == len(shapes) and result["threads"] == torch.get_num_threads()
    assert result["ratio"] == pytest.approx(result["step_ms"] / result["floor_ms"])
    assert {tuple(s["shape"]) for s in result["per_shape"]} == set(shapes)
    assert sum(s["count"] for s in result["per_shape"]) == len(shapes)


def test_a_product_the_floor_cannot_time_is_refused():
    a = torch.randn(4, 5)
    with pytest.raises(NotImplementedError, match="mv"):
        floor.products(lambda: torch.mv(a, a[0]))


def test_batched_products_are_counted_with_their_batch_and_timed_as_batched():
    a, b = torch.randn(3, 4, 5), torch.randn(3, 5, 6)
    shapes = floor.products(lambda: (torch.bmm(a, b), torch.baddbmm(torch.zeros(3, 4, 6), a, b)))
    assert shapes == [(3, 4, 5, 6), (3, 4, 5, 6)]
    label, fn, seconds = floor._fastest_layout(3, 4, 5, 6, repeats=3)
    assert fn().shape in {(3, 4, 6), (3, 6, 4)} and seconds > 0


def test_the_group_table_is_rewritten_alone_and_the_other_jobs_leave_it(tmp_path, monkeypatch):
    (tmp_path / "docs").mkdir()
    page = tmp_path / "docs" / "speed.md"
    page.write_text("intro\n<!-- benchmark:begin -->\nold main\n<!-- benchmark:end -->\nafter\n")
    monkeypatch.setattr(hnn.tasks, "repo_root", lambda: tmp_path)
    first = benchmark_report.benchmark_section(None, "stamp A\n\ngroup table A")
    assert first.startswith("old main") and first.endswith("stamp A\n\ngroup table A")
    page.write_text(f"intro\n<!-- benchmark:begin -->\n{first}\n<!-- benchmark:end -->\nafter\n")
    again = benchmark_report.benchmark_section("new main", None)          # a run without the group job
    assert again == f"new main\n\n{benchmark_report.GROUP_MARK}\n\nstamp A\n\ngroup table A"
    page.write_text(f"intro\n<!-- benchmark:begin -->\n{again}\n<!-- benchmark:end -->\nafter\n")
    assert benchmark_report.benchmark_section(None, "stamp B\n\ngroup table B").count("group table") == 1


def test_others_load_is_the_machines_busy_seconds_less_this_processs_per_wall_second():
    """The arithmetic on synthetic snapshots (a real machine's load is whatever else runs on it)."""
    from hnn_analysis.provenance import busy_seconds, others_load
    # user nice system idle iowait irq softirq steal (ticks): busy = 100 + 5 + 50 + 3 + 2 + 0 = 160
    assert busy_seconds("cpu  100 5 50 1000 20 3 2 0 0 0", 100) == pytest.approx(1.6)
    start = {"wall": 10.0, "own": 1.0, "machine_busy": 100.0}
    # 3.7 busy seconds over 2 s of wall, 1.5 of them this process's: others kept 1.1 cores busy
    assert others_load(start, {"wall": 12.0, "own": 2.5, "machine_busy": 103.7}) == pytest.approx(1.1)
    # this process's own work is not another's: a busy loop alone reads 0
    assert others_load(start, {"wall": 11.0, "own": 2.0, "machine_busy": 101.0}) == pytest.approx(0.0)
    # rounding of the tick counters never reads below 0
    assert others_load(start, {"wall": 11.0, "own": 2.0, "machine_busy": 100.99}) == 0.0
