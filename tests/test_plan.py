"""analysis/plan.py: a study says its stages and their estimates from measured per-run costs before it starts."""
import re
from pathlib import Path

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
    # a quick run prices the datasets it builds and its evaluation at their declared costs (TaskSpec's)
    assert lines[start + 1].startswith("  build 1 dataset: "), lines[start + 1]
    train = lines[start + 2]
    assert re.match(r"  train 2 runs: about \d+ s \(each run's steps at its config's one-thread rate, measured now\)",
                    train), train
    assert lines[start + 3].startswith("  evaluate 1 rows: about 5 s (each task's declared evaluation")
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


def test_a_stage_over_its_share_is_said_before_the_study_starts(capsys):
    stages = [plan.Stage("train", 3, "runs", 50.0, "measured", share=40.0),
              plan.Stage("measure", 3, "models", 10.0, "declared", share=30.0), plan.Stage("draw", 1, "figure")]
    text = plan.say("quick", stages)
    lines = text.splitlines()
    assert lines[1].endswith("; OVER its share of 40 s") and lines[2].endswith("; its share 30 s")
    assert "share" not in lines[3] and stages[0].over and not stages[1].over and not stages[2].over


def test_a_quick_fit_takes_at_most_its_rows_and_a_cell_keeps_its_fraction_where_that_is_fewer(tmp_path):
    from hnn_analysis.scenes import scene_rungs
    config = hnn.tasks.task_config("spring", {"model": "hnn", "fit": "library", "save_dir": str(tmp_path)})
    rows = scene_rungs.training_rows(config)
    cut = scene_rungs.capped(config, rows // 4)
    assert abs(scene_rungs.training_rows(cut) - rows // 4) <= 1 and cut.key() != config.key()
    assert scene_rungs.capped(config, rows) is config


def test_the_reference_box_prices_a_run_by_its_tasks_declared_cost_and_a_fit_by_its_rows():
    spring = sweep.Job("s", "spring", hnn.tasks.task_config("spring", {"total_steps": 99}))
    per_step = hnn.task_spec("spring").cost / hnn.tasks.task_config("spring", {}).total_steps
    assert plan.reference_seconds(spring) == pytest.approx(plan.REFERENCE_RUN_SECONDS + 100 * per_step)
    fit = sweep.Job("f", "spring", hnn.tasks.task_config("spring", {"fit": "library"}))
    assert plan.reference_seconds(fit, 1000) == pytest.approx(plan.REFERENCE_RUN_SECONDS
                                                              + 1000 * plan.REFERENCE_FIT_ROW_SECONDS)
    with pytest.raises(ValueError, match="fit_rows"):
        plan.reference_seconds(fit)
    # the plan's own measuring, as plan.timed measures: once a config whatever its seed, a one-step run once a task
    # trained by steps (a fit's estimate is its own solves)
    seeds = [sweep.Job(f"s{seed}", "spring", hnn.tasks.task_config("spring", {"total_steps": 99, "seed": seed}))
             for seed in (0, 1, 2)]
    pend_fit = sweep.Job("p", "pend", hnn.tasks.task_config("pend", {"fit": "library"}))
    stage = plan.reference_timing([*seeds, fit, pend_fit])
    assert stage.what == "plan" and stage.count == 3
    assert stage.seconds == pytest.approx(3 * plan.REFERENCE_TIMING_SECONDS + plan.REFERENCE_RUN_SECONDS)


def test_the_quick_paper_reproduction_plans_within_its_budget_on_the_reference_box():
    """reproduce.py --quick on the reference box (declared costs: each run's, each task's TaskSpec.data_cost and
    evaluate_cost), every stage priced, within commands.QUICK_BUDGETS; a task whose dataset is dear (the pixels'
    frames) is left out of its default tasks, and named it is priced the same way."""
    from hnn_analysis import commands
    study = reproduce.study
    tasks = study.quick_tasks(hnn.tasks.paper_tasks())
    assert "pixels" not in tasks and "spring" in tasks
    stages = study.reference_plan(tasks)
    assert [s.what for s in stages] == ["plan", "train", "build", "evaluate"] and all(s.seconds > 0 for s in stages)
    assert sum(s.seconds for s in stages) <= commands.QUICK_BUDGETS["reproduce"]
    # the rows' evaluation is each task's row at its declared cost; a variant row (the 3-body's cleaned orbits)
    # draws no figure and is priced at none: it took 0.0 s of the six rows' 17 s on a quiet box
    rows = study.table_rows(tasks, True, [0])
    variants = [row for row in rows if row["row"] != row["task"]]
    assert [row["row"] for row in variants] == ["3body-clean"]
    assert stages[3].count == len(rows) and stages[3].seconds == pytest.approx(
        sum(hnn.task_spec(task).evaluate_cost for task in tasks))
    with_pixels = study.reference_plan([*tasks, "pixels"])
    assert sum(s.seconds for s in with_pixels) > sum(s.seconds for s in stages) + hnn.task_spec("pixels").data_cost


def test_the_quick_peers_table_plans_within_its_budget_on_the_reference_box():
    """peers.py --quick on the reference box (declared costs: the chain's TaskSpec.data_cost, peer_plan.QUICK_COSTS
    by kind and bobs), every stage priced, within commands.QUICK_BUDGETS; a Lagrangian kind's run is priced above
    the chain's mean step (its Hessians), and a run's measuring grows with its bobs."""
    from hnn_analysis import commands
    from hnn_analysis.chains import peer_plan
    stages = peer_plan.reference_plan()
    assert [s.what for s in stages] == ["plan", "build", "train", "measure", "time"] and all(s.seconds > 0
                                                                                          for s in stages)
    jobs = peer_plan.plan({"kinds": peer_plan.kinds(), **peer_plan.QUICK}, Path("runs"))
    assert stages[2].count == len(jobs) == stages[0].count      # one seed: a config a run, each timed once
    assert sum(s.seconds for s in stages) <= commands.QUICK_BUDGETS["peers"]
    # a dataset a CHNN row: the LNN protocol's states are drawn with their derivatives (no rollout to build)
    assert stages[1].count == len(peer_plan.QUICK["bobs"])
    assert stages[1].seconds == pytest.approx(stages[1].count * hnn.task_spec("chain").data_cost)
    # the declared costs move the plan as they should: more bobs, dearer runs and measuring
    more = peer_plan.reference_plan({**peer_plan.QUICK, "bobs": (1, 2, 3)})
    assert more[2].seconds > stages[2].seconds and more[3].seconds > stages[3].seconds


def test_a_quick_peers_run_is_priced_by_its_kind_and_bobs_and_an_lnn_run_by_its_own():
    """peer_plan.quick_training / quick_measuring: a CHNN-row run its fixed part and its kind's steps a bob (the
    Lagrangian kinds' Hessians grow with the bobs; a kind without a per-bob cost is a fixed run), its measuring a
    bob's rollouts; an LNN-protocol run its own declared training and measuring, whatever its kind."""
    from hnn_analysis.chains import peer_plan
    costs = peer_plan.QUICK_COSTS
    jobs = {job.key: job for job in peer_plan.plan({"kinds": peer_plan.kinds(), **peer_plan.QUICK}, Path("runs"))}
    lagrangian, baseline = jobs["chain2/lagrangian/seed0"], jobs["chain1/baseline/seed0"]
    assert peer_plan.quick_training(lagrangian) == pytest.approx(costs["train_run"]
                                                                 + 2 * costs["train_bob"]["lagrangian"])
    assert peer_plan.quick_training(baseline) == pytest.approx(costs["train_run"])
    assert peer_plan.quick_measuring(lagrangian) == pytest.approx(2 * costs["measure_bob"])
    lnn = jobs["lnn/lagrangian/seed0"]
    assert lnn.config.bobs == 2 and peer_plan.quick_training(lnn) == pytest.approx(costs["train_lnn"])
    assert peer_plan.quick_measuring(lnn) == pytest.approx(costs["measure_lnn"])
    stages = peer_plan.reference_plan()
    assert stages[2].seconds == pytest.approx(sum(map(peer_plan.quick_training, jobs.values())))
    assert stages[3].seconds == pytest.approx(sum(map(peer_plan.quick_measuring, jobs.values())))


def test_a_fresh_quick_peers_sitting_prices_its_measuring_and_timing_before_it_starts(tmp_path, capsys):
    """peers.py --quick with nothing recorded: its plan prices the measuring of every run at its declared cost and
    the table's timing of the kinds (the plan of another sitting: from the record, or timed as it runs)."""
    from hnn_analysis.chains import peer_plan, peer_record
    settings = {"kinds": peer_plan.kinds(), **peer_plan.QUICK}
    jobs = peer_plan.plan(settings, tmp_path)
    record = peer_record.load(tmp_path / "peers-runs.json", settings)
    peer_record.plan_sitting(record, [], jobs, {}, settings, tmp_path, range(1), 1, quick=True)
    lines = capsys.readouterr().out.splitlines()
    measure = sum(map(peer_plan.quick_measuring, jobs))
    assert lines[2] == (f"  measure {len(jobs)} runs' rollouts (each as it finishes training): about "
                        f"{measure:.0f} s (each run's declared measuring by its bobs)"), lines
    assert lines[3].startswith(f"  time {len(settings['kinds'])} kinds: about "
                               f"{peer_plan.QUICK_COSTS['timing']:.0f} s"), lines
    peer_record.plan_sitting(record, [], jobs, {}, settings, tmp_path, range(1), 1, quick=False, table=False)
    lines = capsys.readouterr().out.splitlines()
    assert lines[2].endswith("timed as it runs, from its first units") and not lines[3].startswith("  time"), lines


def test_the_quick_scene_study_plans_within_its_budget_on_the_reference_box():
    """Every stage of scene_study.py --quick on the reference box (declared costs: plan.reference_seconds, each
    scene's TaskSpec.data_cost, scene_measure's), each within its share and all within commands.QUICK_BUDGETS; a
    rollout's worst case is its budget (scene_measure.QUICK_ROLLOUT_CALLS), which the plan says as its "at most"."""
    from hnn_analysis import commands
    from hnn_analysis.scenes import scene_stages
    stages = scene_stages.reference_plan()
    assert [s.what for s in stages] == ["plan", "train", "build", "measure"]
    assert not [s.what for s in stages if s.over]
    assert sum(s.seconds for s in stages) <= commands.QUICK_BUDGETS["scene_study"]
    # the shares are of the budget: they leave the start and the cards a part of it
    assert sum(scene_stages.QUICK_SHARES.values()) <= commands.QUICK_BUDGETS["scene_study"]


def test_a_quick_rollout_budget_is_in_field_calls_so_the_same_rollouts_stop_on_every_box():
    """scene_measure.QUICK_ROLLOUT_CALLS is its seconds at the reference rate; within rollout_budget(calls=N) a
    stiff field (dx/dt = -1e5 x: dopri5 at its stability limit, ~2e5 calls over t in [0, 1]) is called exactly N
    times, whatever the box's speed, and a healthy one (dx/dt = -x, a few dozen calls) rolls out as unbounded."""
    import numpy as np
    import torch
    from hnn_analysis.scenes import scene_measure
    assert scene_measure.QUICK_ROLLOUT_CALLS == round(scene_measure.QUICK_ROLLOUT_SECONDS
                                                      / plan.REFERENCE_FIELD_CALL_SECONDS)
    calls = [0]

    def counted(rate):
        def f(x):
            calls[0] += 1
            return -rate * x
        return f
    x0, t = torch.ones(3, 2, dtype=torch.float64), np.linspace(0.0, 1.0, 5)
    with hnn.evaluation.rollout_budget(calls=500, why="a test's"):
        stiff = hnn.evaluation.rollout_errors(counted(1e5), torch.ones(3, 5, 2, dtype=torch.float64), t)
    # the batch stops at its 500th call, and each path then at its first, without calling the field
    assert calls[0] == 500 and stiff["stopped"] == 3 and stiff["blew_up"] == 0
    free, _ = hnn.evaluation.model_rollout(counted(1.0), x0, t)
    with hnn.evaluation.rollout_budget(calls=500):
        bounded, failed = hnn.evaluation.model_rollout(counted(1.0), x0, t)
    assert failed == 0 and torch.equal(bounded, free)
    with pytest.raises(ValueError, match="give one of them"):
        with hnn.evaluation.rollout_budget(1.0, calls=10):
            pass
    with pytest.raises(ValueError, match="positive whole number"):
        with hnn.evaluation.rollout_budget(calls=0):
            pass


def test_quick_budgets_sets_each_stage_of_a_plan_beside_the_seconds_its_run_recorded(tmp_path):
    """quick_budgets.py reads the stages' seconds a quick mode wrote (reproduce's results.json, peers.json's meta;
    numbers only, a record without them read as none) and sets each of its plan's stages beside them: peers.py
    measures each run inside the training's wall time, so its training is that wall less the measuring."""
    import json
    from hnn_analysis.benchmarks import quick_budgets, timed_commands
    (tmp_path / "peers.json").write_text(json.dumps({"meta": {"seconds": {"training": 90.0, "measuring": 50.0,
                                                                          "timing": 8.0}}}))
    (tmp_path / "peers-runs.json").write_text(json.dumps({"measuring": {"rtol": 1e-7}, "runs": {}}))
    (tmp_path / "broken.json").write_text("{")
    seconds = timed_commands.recorded_seconds(tmp_path)
    assert seconds == {"training": 90.0, "measuring": 50.0, "timing": 8.0}
    plan_seconds = {"build": 5.0, "train": 60.0, "measure": 50.0, "time": 4.0}
    rows = quick_budgets.stage_ratios("peers", plan_seconds, seconds)
    assert [(r["stages"], r["plan"], r["measured"], r["ratio"]) for r in rows] == [
        (["train"], 60.0, 40.0, 1.5), (["measure"], 50.0, 50.0, 1.0), (["time"], 4.0, 8.0, 0.5)]
    # reproduce: its datasets built and configs timed are what its total leaves beside the training and evaluation
    rows = quick_budgets.stage_ratios("reproduce", {"plan": 1.0, "build": 1.0, "train": 10.0, "evaluate": 20.0},
                                      {"training": 5.0, "evaluation": 16.0, "total": 25.0, "jobs": 1})
    assert [(r["measured"], r["ratio"]) for r in rows] == [(4.0, 0.5), (5.0, 2.0), (16.0, 1.25)]
    # the scene study: its training's wall holds its datasets, its configs' timing and the runs' sweep
    rows = quick_budgets.stage_ratios("scene_study", {"plan": 2.0, "build": 1.0, "train": 12.0, "measure": 10.0},
                                      {"training": 9.0, "sweep": 6.0, "measure": 20.0})
    assert [(r["measured"], r["ratio"]) for r in rows] == [(3.0, 1.0), (6.0, 2.0), (20.0, 0.5)]
    assert quick_budgets.stage_ratios("peers", plan_seconds, {}) == []
