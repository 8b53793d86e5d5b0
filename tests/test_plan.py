"""analysis/plan.py: a study says its stages and their estimates from measured per-run costs before it starts."""
import re

import pytest

import hnn
from hnn.sweeps import sweep
from hnn_analysis import plan
from hnn_analysis.paper import reproduce


def test_runs_are_shared_over_the_workers_longest_first():
    assert plan.schedule([3.0, 3.0, 2.0, 2.0, 2.0], 1) == 12.0
    # the sweep's own order: the longest first, each to the first free worker (3 | 3, then 2 2 | 2)
    assert plan.schedule([2.0, 3.0, 2.0, 3.0, 2.0], 2) == 7.0
    assert plan.schedule([5.0, 1.0], 3) == 5.0 and plan.schedule([], 2) == 0.0


def test_a_jobs_training_is_measured_once_per_config_whatever_its_seed(tmp_path):
    calls = []

    def cost(task, args):
        calls.append((task, args["seed"]))
        return {"seconds": 2.5 if args["model"] == "hnn" else 1.0}
    jobs = [sweep.Job(f"spring/{kind}/seed{seed}", "spring",
                      hnn.tasks.task_config("spring", {"model": kind, "seed": seed, "save_dir": str(tmp_path)}))
            for kind in ("baseline", "hnn") for seed in (0, 1, 2)]
    timed = plan.timed(jobs, cost, overhead_of=lambda job: 0.5)       # a run's cost beside its steps, once a task
    assert len(calls) == 2 and [j.expected_seconds for j in timed] == [1.5] * 3 + [3.0] * 3
    stage = plan.training(timed, 2)
    assert (stage.count, stage.seconds) == (6, 7.5)        # two workers: 3 + 3 | 3 + 1.5 + 1.5 + 1.5
    # the default overhead: a one-step run of the task, timed, in a folder of its own
    assert 0 < plan.overhead(jobs[0]) and not any(tmp_path.iterdir())


def test_a_study_prints_its_plan_with_a_measured_estimate_before_it_starts(tmp_path, capsys):
    reproduce.main(["--quick", "--steps", "3", "--tasks", "spring", "--no-figures", "--out", str(tmp_path)])
    lines = capsys.readouterr().out.splitlines()
    start = lines.index(next(line for line in lines if line.startswith("reproduce: plan on this box")))
    trained = next(i for i, line in enumerate(lines) if " trained " in line)
    assert start < trained, lines
    train = lines[start + 1]
    assert re.match(r"  train 2 runs: about \d+ s \(each run's steps at its config's one-thread rate, measured now\)",
                    train), train
    assert lines[start + 2].startswith("  evaluate 1 rows")
    # a rerun reuses both runs: nothing to train, and it says so before it starts
    reproduce.main(["--quick", "--steps", "3", "--tasks", "spring", "--no-figures", "--out", str(tmp_path)])
    out = capsys.readouterr().out
    assert "reproduce: 2 runs reused, 0 to train" in out and "  train 0 runs: about 0 s" in out


@pytest.mark.parametrize("done, said", [(0.0, ""), (5.0, ", about 5 s left"), (10.0, "")])
def test_a_stage_says_its_time_left_at_its_recent_pace(monkeypatch, done, said):
    now = [100.0]
    monkeypatch.setattr(plan.time, "perf_counter", lambda: now[0])
    ahead = plan.Ahead(10.0)
    now[0] += 5.0
    assert ahead.tag(done) == said
