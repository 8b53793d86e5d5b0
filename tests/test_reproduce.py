"""analysis/reproduce.py: the table writer, the reuse rule, one task end to end, and --jobs."""
import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
import torch

import hnn
from hnn_analysis.paper import registry, reproduce, study, tables
from hnn_analysis import commands, pages, plotting, readme
from hnn.sweeps import sweep

TINY = 20          # training steps of the end-to-end runs


def _row(train, test, energy):
    """One task's row of results.json: (mean, ±) pairs for both models."""
    return {kind: {"train_loss": list(train[kind]), "test_loss": list(test[kind]),
                   "energy_mse_paper": list(energy[kind])} for kind in ("baseline", "hnn")}


@pytest.fixture
def results():
    """A hand-made results dict against the paper's spring numbers (hnn.tasks.PAPER)."""
    # spring paper: train baseline 3.7134e-02 ± 1.9143e-03, hnn 3.6933e-02 ± 1.9128e-03
    #               test baseline 3.6656e-02 ± 1.8652e-03, energy hnn 3.8416e-04 ± 6.53e-05
    edge = 3.7134e-02 + 1.9143e-03          # exactly at the paper's ±: within
    train = {"baseline": (edge, 1e-3), "hnn": (3.6933e-02 - 1.9128e-03 * 1.01, 1e-3)}   # within, better
    test = {"baseline": (3.6656e-02 + 1.8652e-03 * 1.01, 1e-3), "hnn": (3.5928e-02, 1e-3)}  # worse, within
    energy = {"baseline": (1.7077e-01, 1e-2), "hnn": (3.8416e-04 - 6.53e-05, 1e-5)}        # within, within (edge)
    return {"meta": {"command": "python analysis/reproduce.py --quick", "date": "2026-01-01", "commit": "abc",
                     "seed": 0, "seeds": [0], "mode": "QUICK smoke run", "quick": True, "steps": 300,
                     "torch": "x", "available": ["spring", "pend"]},
            "tasks": {"spring": _row(train, test, energy)},
            "skipped": {"pend": "no data"},
            "seconds": {"tasks": {"spring": {"data": 0.5, "train": {"baseline": 1.0, "hnn": 2.0},
                                             "evaluate": 3.0, "figures": 4.0}},
                        "training": 3.5, "evaluation": 7.0, "total": 10.5, "jobs": 1, "threads_per_job": 1}}


def _cell(table: str, title: str, kind: str) -> str:
    """The 'ours' cell of the spring row for ``kind`` in the table headed ``title``."""
    section = table.split(f"**{title}**", 1)[1]
    row = next(line for line in section.splitlines() if line.startswith(f"| spring | {kind} |"))
    return row.split("|")[4].strip()


def test_compare_edges():
    assert tables.compare((1.1, 0.0), (1.0, 0.1)) == "within"        # 1.1 - 1.0 > 0.1 in floats
    assert tables.compare((0.9, 0.0), (1.0, 0.1)) == "within"
    assert tables.compare((1.1000001, 0.0), (1.0, 0.1)) == "worse"
    assert tables.compare((0.8999999, 0.0), (1.0, 0.1)) == "better"
    assert tables.compare(None, (1.0, 0.1)) is None


def test_tables_marks_missing_and_stages(results):
    quick = tables.tables_markdown(results)
    results["meta"].update(quick=False, steps=500, mode="500 steps per model: not the paper's settings")
    short = tables.tables_markdown(results)       # --steps without --quick: not the paper's settings either
    results["meta"].update(steps=None, mode="full settings")       # marks are for the paper's settings alone
    table = tables.tables_markdown(results)
    for unmarked in (quick, short):
        assert not any(_cell(unmarked, title, kind)[-1] in tables.MARKS.values() for title in ("Train loss", "Test loss",
                       "Energy MSE") for kind in ("baseline", "hnn")), unmarked
    assert "--steps 500 trains 500 steps a model" in short and tables.LEGEND not in short
    marks = tables.MARKS
    assert _cell(table, "Train loss", "baseline").endswith(marks["within"])    # exactly at the ±
    assert _cell(table, "Train loss", "hnn").endswith(marks["better"])
    assert _cell(table, "Test loss", "baseline").endswith(marks["worse"])
    assert _cell(table, "Test loss", "hnn").endswith(marks["within"])
    assert _cell(table, "Energy MSE", "baseline").endswith(marks["within"])
    assert _cell(table, "Energy MSE", "hnn").endswith(marks["within"])
    assert tables.LEGEND in table and "QUICK" in quick.splitlines()[0]
    assert "| 1.05x |" in table and "| 1.05x |" in quick                                 # the ratio column stays
    # tasks absent from the checkout are listed; a present one without data is reported as skipped
    missing = next(line for line in table.splitlines() if line.startswith("Not yet in this checkout"))
    assert "real" in missing and "2body" in missing and "pixels" in missing and "spring" not in missing
    assert "Skipped pend" in table
    assert "| spring | 0.5 | 1.0 | 2.0 | 3.0 | 4.0 |" in table and "total 10.5 s" in table


def test_every_task_names_known_figures_and_costs_more_when_it_trains_longer():
    for task in hnn.available_tasks():
        spec = hnn.task_spec(task)
        assert spec.figures and set(spec.figures) <= set(registry.FIGURES), task
    assert hnn.task_spec("3body").cost > hnn.task_spec("spring").cost


def test_a_sweep_reuses_a_run_of_the_same_config_and_keeps_it_beside_others(tmp_path):
    def job(**fields):
        return sweep.Job("spring/hnn/seed0", "spring",
                         hnn.tasks.task_config("spring", {"save_dir": str(tmp_path), "total_steps": 3, **fields}))

    trained, _ = sweep.train_jobs([job()], 1, tmp_path / "logs")
    first = trained["spring/hnn/seed0"]
    metrics = json.loads((first / "metrics.json").read_text())
    assert metrics["train_seconds"] > 0
    stamp = (first / "model.tar").stat().st_mtime_ns
    found, todo = sweep.reuse([job()])
    assert found == {"spring/hnn/seed0": first} and todo == []
    for other in (dict(total_steps=4), dict(learn_rate=0.002)):
        found, todo = sweep.reuse([job(**other)])
        assert found == {} and len(todo) == 1, other
        second = sweep.train_jobs(todo, 1, tmp_path / "logs")[0]["spring/hnn/seed0"]
        assert second != first and (first / "model.tar").stat().st_mtime_ns == stamp      # the first is kept
    assert json.loads((second / "args.json").read_text())["learn_rate"] == 0.002


def _losses(results: dict) -> dict:
    return {(task, kind): (row[kind]["train_loss"], row[kind]["test_loss"])
            for task, row in results["tasks"].items() for kind in ("baseline", "hnn")}


def test_quick_end_to_end_and_jobs(tmp_path):
    """One task end to end (results.json, tables.md, figures), then --jobs 2 on fresh runs.

    Both layouts train with one thread per process (this process is set to one thread here, and
    --jobs = the cores gives each worker cores // jobs = 1), so the same seed gives the same
    floating-point operations and the numbers must agree exactly. (The thread count changes the
    order of float sums, so runs at different thread counts differ in the last bits, and
    training amplifies that.)
    """
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        one = reproduce.main(["--quick", "--steps", str(TINY), "--tasks", "spring", "--out", str(tmp_path / "a")])
    finally:
        torch.set_num_threads(threads)
    out = tmp_path / "a"
    saved = json.loads((out / "results.json").read_text())
    assert saved["meta"]["quick"] and "QUICK" in saved["meta"]["mode"] and saved["meta"]["steps"] == TINY
    assert saved["tasks"]["spring"]["hnn"]["total_steps"] == TINY
    seconds = saved["seconds"]
    assert {"data", "train", "evaluate", "figures"} <= set(seconds["tasks"]["spring"])
    assert seconds["total"] >= seconds["training"] > 0
    numbers = saved["tasks"]["spring"]["figure_numbers"]
    assert len(numbers["reversibility"]["error"]["hnn"]) == len(numbers["reversibility"]["T"])
    assert numbers["energy_bump"]["H_after"] > numbers["energy_bump"]["H_before"]   # the bump adds energy
    assert (out / "tables.md").read_text().startswith("**QUICK")
    for name in ("fields", "integration", "energy-paper", "energy-corrected", "energy-bump", "reversibility"):
        path = out / "figures" / f"spring-{name}.png"
        assert path.stat().st_size > 10_000, path

    jobs = max(2, sweep.cores())
    two = reproduce.main(["--quick", "--steps", str(TINY), "--tasks", "spring", "--out", str(tmp_path / "b"),
                          "--jobs", str(jobs), "--no-figures"])
    assert two["seconds"]["jobs"] == jobs and two["seconds"]["threads_per_job"] == 1
    assert _losses(two) == _losses(one)
    for kind in ("baseline", "hnn"):
        assert two["tasks"]["spring"][kind]["energy_mse_paper"] == one["tasks"]["spring"][kind]["energy_mse_paper"]


def test_readme_timing_section_comes_from_saved_results(results, tmp_path, monkeypatch):
    results["meta"]["cores"] = 2
    text = pages.timing_text(results)
    assert text.startswith("Generated by `python analysis/reproduce.py --quick` on 2026-01-01")
    assert "| spring | 0.5 | 1.0 | 2.0 | 3.0 | 4.0 |" in text and "total 10.5 s" in text
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "speed.md").write_text("a\n<!-- full-run:begin -->\nold\n<!-- full-run:end -->\nb\n")
    (tmp_path / "experiment-x").mkdir()
    monkeypatch.setenv("HNN_REPO", str(tmp_path))
    saved = tmp_path / "results.json"
    saved.write_text(json.dumps(results))
    readme.main(["timing", str(saved)])
    content = (tmp_path / "docs" / "speed.md").read_text()
    assert "old" not in content and "| spring | 0.5 |" in content and content.endswith("<!-- full-run:end -->\nb\n")
    results["seconds"]["tasks"] = {}
    with pytest.raises(ValueError, match="no stage times"):
        pages.timing_text(results)


def test_variant_rows_train_under_their_own_name_and_keep_the_papers_numbers(tmp_path, monkeypatch, capsys):
    variant = {"wide": ({"hidden_dim": 16}, "a narrower net, for the test")}
    task = hnn.load_task("spring", "task")
    monkeypatch.setattr(task, "TASK", dataclasses.replace(task.TASK, variants=variant))
    results = reproduce.main(["--quick", "--steps", "3", "--tasks", "spring", "--no-figures", "--out", str(tmp_path)])
    assert list(results["tasks"]) == ["spring", "spring-wide"]
    row = results["tasks"]["spring-wide"]
    assert row["task"] == "spring" and row["note"] == "a narrower net, for the test"
    [run] = (tmp_path / "runs").glob("spring-wide-hnn-seed0-*")
    assert json.loads((run / "args.json").read_text())["hidden_dim"] == 16
    table = (tmp_path / "tables.md").read_text()
    assert "| spring-wide | hnn | 3.5928e-02 ± 1.83e-03 |" in table          # the paper's spring number beside it
    assert "- **spring-wide**: a narrower net, for the test" in table


def test_a_task_that_cannot_run_is_reported_once(tmp_path, monkeypatch, capsys):
    real = hnn.load_task("real")
    monkeypatch.setenv("HNN_DATA_DIR", str(tmp_path / "nowhere"))
    results = reproduce.main(["--quick", "--steps", "2", "--seeds", "2", "--tasks", "real", "--no-figures",
                              "--out", str(tmp_path)])
    out = capsys.readouterr().out
    assert out.count("were not found") == 1 + 1          # once when it failed, once in the printed tables
    assert "real" in results["skipped"] and real.DATA_FILE in results["skipped"]["real"]
    assert not results["tasks"]


def test_quick_figures_say_quick_in_their_titles(tmp_path):
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots()
    fig.suptitle("spring: fields")
    plotting.set_stamp("QUICK smoke run")
    try:
        plotting.save_figure(fig, tmp_path / "a.png")
    finally:
        plotting.set_stamp("")
    assert fig._suptitle.get_text() == "QUICK smoke run\nspring: fields" and (tmp_path / "a.png").stat().st_size > 0
    fig, ax = plt.subplots()
    plotting.save_figure(fig, tmp_path / "b.png")
    assert fig._suptitle is None                          # no stamp outside quick runs


def test_quick_measures_each_energy_protocol_on_fewer_trials_and_says_each_cut(tmp_path):
    cuts = study.quick_cuts(["spring", "pixels"], study.QUICK_STEPS)
    assert cuts == [f"{study.QUICK_STEPS} training steps a model of the tasks' own 2000 (spring), 10000 (pixels)",
                    "pixels: trials 20 of 200", "energy MSE: 5 trials of each protocol's 15"]
    assert study.quick_cuts(["pixels"], None) == ["pixels: trials 20 of 200"]     # its own evaluate: kept
    config = hnn.tasks.task_config("spring", {"total_steps": TINY, "save_dir": str(tmp_path)})
    trained, _ = study.load_runs("spring", {"hnn": hnn.run_experiment(config)})
    full, quick = registry.evaluate(trained), registry.evaluate(trained, study.QUICK_TRIALS)
    for name, result in quick.items():
        truth, all_truth = np.asarray(result["energy_truth"]), np.asarray(full[name]["energy_truth"])
        assert len(truth) == 5 and len(all_truth) == 15
        # the same first trials: a quick run's 5 starts are the full protocol's first 5 (their truths, solved
        # as one batch of other size by an adaptive solver at atol 1e-6, agree to that tolerance)
        assert np.array_equal(result["x0"], full[name]["x0"][:5]), name
        np.testing.assert_allclose(truth, all_truth[:5], atol=1e-3)
        assert "5 trials" in result["description"]


def test_the_recorded_command_names_no_folder_of_this_machine(tmp_path):
    root = hnn.tasks.repo_root()
    command = commands.portable_command(["--out", str(root / "results-x"), "--jobs", "2", "--out", str(tmp_path)])
    assert command == "python analysis/reproduce.py --out results-x --jobs 2 --out DIR"


@pytest.mark.parametrize("argv, match", [
    (["--jobs", "0"], "--jobs: must be an integer >= 1, got '0'"),
    (["--tasks", "nosuch"], "--tasks nosuch: no such task here"),
    (["--quick", "--update-docs"], "drop --quick"),
])
def test_bad_values_exit_with_one_error_line(argv, match, capsys):
    with pytest.raises(SystemExit) as info:
        reproduce.main(argv)
    err = capsys.readouterr().err
    assert info.value.code == 2 and match in err
    assert [line for line in err.splitlines() if line.startswith("error:")] == [err.splitlines()[-1]]
    assert "Traceback" not in err


def _git(root, *args):
    import subprocess
    subprocess.run(["git", "-c", "user.name=t", "-c", "user.email=t@t", *args], cwd=root, check=True,
                   capture_output=True)


def _head(root) -> str:
    import subprocess
    return subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=root, capture_output=True, text=True,
                          check=True).stdout.strip()


def test_staleness_check_flags_a_page_stamped_before_a_code_change(tmp_path, monkeypatch, capsys):
    for code in ("hnn/x.py", "experiment-x/data.py"):
        (tmp_path / code).parent.mkdir()
        (tmp_path / code).write_text("a = 1\n")
    (tmp_path / "README.md").write_text("<!-- headline:begin -->\nnot stamped yet\n<!-- headline:end -->\n")
    _git(tmp_path, "init", "-q")
    _git(tmp_path, "add", ".")
    _git(tmp_path, "commit", "-qm", "code")
    made = _head(tmp_path)
    readme_text = f"<!-- headline:begin -->\nfrom `cmd` (commit {made}, today)\n<!-- headline:end -->\n"
    (tmp_path / "README.md").write_text(readme_text)
    _git(tmp_path, "commit", "-qam", "the page, stamped with the code that made it")
    monkeypatch.setenv("HNN_REPO", str(tmp_path))
    assert pages.stale(["headline"]) == []                      # a docs-only commit after the stamp is fine
    (tmp_path / "hnn" / "x.py").write_text("a = 2\n")
    _git(tmp_path, "commit", "-qam", "a code change")
    [line] = pages.stale(["headline"])
    assert f"stamped {made}, older than the last change" in line and pages.REFRESH["headline"] in line
    with pytest.raises(SystemExit) as exit_code:
        readme.main(["check"])
    assert exit_code.value.code == 1 and made in capsys.readouterr().out
    (tmp_path / "README.md").write_text(readme_text.replace(made, _head(tmp_path)))
    assert pages.stale(["headline"]) == []
    (tmp_path / "experiment-x" / "data.py").write_text("a = 2\n")     # a task's code counts too
    _git(tmp_path, "commit", "-qam", "a task change")
    assert len(pages.stale(["headline"])) == 1
    (tmp_path / "README.md").write_text(readme_text.replace(made, _head(tmp_path)))
    (tmp_path / "hnn" / "x.py").write_text("a = 3\n")
    _git(tmp_path, "commit", "-qam", f"a message changes\n\n{pages.UNCHANGED} only what is printed")
    assert pages.stale(["headline"]) == []                      # a commit that says it moves no number
    # a branch of such commits merged: the merge's own message says nothing, its commits do
    _git(tmp_path, "checkout", "-qb", "side")
    (tmp_path / "hnn" / "x.py").write_text("a = 4\n")
    _git(tmp_path, "commit", "-qam", f"a rename\n\n{pages.UNCHANGED} names only")
    _git(tmp_path, "checkout", "-q", "-")
    (tmp_path / "hnn" / "y.py").write_text("b = 1\n")                  # main changes hnn/ meanwhile too
    _git(tmp_path, "add", ".")
    _git(tmp_path, "commit", "-qm", f"a speed-up\n\n{pages.UNCHANGED} bit-identical")
    (tmp_path / "README.md").write_text(readme_text.replace(made, _head(tmp_path)))
    _git(tmp_path, "commit", "-qam", "docs")
    _git(tmp_path, "merge", "-q", "--no-ff", "--no-edit", "side")
    assert pages.stale(["headline"]) == []


def test_headline_is_the_mean_across_seeds_with_the_seed_spread_as_band(results):
    results["meta"].update(seeds=[0, 1, 2], quick=False)
    row = results["tasks"]["spring"]
    per_seed = {seed: {kind: dict(row[kind]) for kind in ("baseline", "hnn")} for seed in "012"}
    row["per_seed"] = per_seed

    def hnn_energy_cell(values):
        for seed, value in zip("012", values):
            per_seed[seed]["hnn"]["energy_mse_paper"] = [value, 1e-5]
        text = tables.headline_markdown(results)
        return text, next(line for line in text.splitlines() if line.startswith("| spring | hnn |")).split("|")

    # paper 3.8416e-04 ± 6.53e-05; ours mean 5e-4, std 1e-4, standard error 5.8e-5: the gap 1.16e-4 is
    # wider than either band, so worse; the spread (std) is 1.5x the paper's ±, so it is named under the table
    text, cells = hnn_energy_cell((4e-4, 5e-4, 6e-4))
    assert cells[3].strip() == "3"
    assert cells[7].strip() == f"0.0005 ± 5.8e-05 {tables.MARKS['worse']}"
    assert "spring hnn energy MSE (0.0004 to 0.0006) 1.5x" in text
    # the same mean, std 3e-4: the standard error 1.7e-4 is now the band and covers the gap
    text, cells = hnn_energy_cell((2e-4, 5e-4, 8e-4))
    assert cells[7].strip() == f"0.0005 ± 0.00017 {tables.MARKS['within']}"


def test_a_task_with_min_seeds_trains_more_seeds_only_across_seeds():
    rows = {r["row"]: r for r in study.table_rows(["spring", "pixels"], quick=True, seeds=[0, 1, 2])}
    assert rows["spring"]["seeds"] == [0, 1, 2]
    assert rows["pixels"]["seeds"] == list(range(hnn.task_spec("pixels").min_seeds)) == [0, 1, 2, 3, 4]
    one = {r["row"]: r for r in study.table_rows(["pixels"], quick=True, seeds=[7])}
    assert one["pixels"]["seeds"] == [7]                         # one seed stays one seed
    jobs = study.plan(list(rows.values()), [0, 1, 2], Path("runs"), 3)
    assert sorted({j.config.seed for j in jobs if j.task == "pixels"}) == [0, 1, 2, 3, 4]


def test_quick_tables_carry_no_marks_against_the_paper_and_say_why(results):
    quick = tables.tables_markdown(results)
    table_rows = [line for line in quick.splitlines() if line.startswith("| ") and "---" not in line]
    assert table_rows and not any(mark in line for line in table_rows for mark in tables.MARKS.values())
    assert tables.QUICK_NOTE in quick and "astronomical" in quick and tables.LEGEND not in quick


@pytest.mark.parametrize("task", ["spring", "real"])
def test_a_tasks_seeds_scored_as_groups_equal_each_seed_scored_alone(task):
    # random small models of each kind at two seeds: the grouping, not the training, is under test
    args = hnn.tasks.task_config(task, {"hidden_dim": 16}).to_dict()
    seeds = []
    for seed in (0, 1):
        models = {}
        for kind in ("baseline", "hnn"):
            torch.manual_seed(seed)
            models[kind] = hnn.kinds.model_from_args({**args, "model": kind, "kind": kind})
        seeds.append(registry.Trained(task, hnn.load_task(task), models, {**args, "seed": seed}))
    together = registry.evaluate_seeds(seeds, num_trials=5)
    for trained, energy in zip(seeds, together):
        alone = registry.evaluate(trained, num_trials=5)
        assert energy.keys() == alone.keys()
        for name, result in alone.items():
            assert energy[name]["description"] == result["description"]
            np.testing.assert_array_equal(energy[name]["truth"], result["truth"])
            for kind in ("baseline", "hnn"):   # the paper's protocols are solve_ivp's: each model integrated alone
                np.testing.assert_array_equal(energy[name][kind]["traj"], result[kind]["traj"])
                assert energy[name][kind]["mse"] == result[kind]["mse"]


def test_thread_spread_sets_the_thread_gap_beside_the_seed_spread():
    from hnn_analysis.paper import thread_spread
    numbers = {"spring": {"hnn": {"energy_mse_paper": {"1": [1e-3, 2e-3, 4e-3], "2": [1.5e-3, 2e-3, 4e-3]}},
                          "baseline": {"test_loss": {"1": [1.0, 1.1, 1.2], "2": [3.0, 1.1, 1.2]}}}}
    meta = {"command": "python analysis/paper/thread_spread.py", "commit": "abcdef1", "seconds": 1.0, "cores": 2,
            "cpu": "x"}
    text = thread_spread.markdown({"meta": meta, "tasks": ["spring"], "seeds": [0, 1, 2], "numbers": numbers})
    assert "| spring | hnn | energy_mse_paper | 0.001, 0.002, 0.004 | 0.0015, 0.002, 0.004 | 1.5x | 4x |" in text
    assert "| spring | baseline | test_loss | 1, 1.1, 1.2 | 3, 1.1, 1.2 | 3x | 1.2x |" in text
    assert "In 1 of 2 rows the thread gap is within the seed spread" in text and "spring baseline test_loss" in text
