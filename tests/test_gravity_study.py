"""The gravity study's rows (analysis/bodies.py --scene gravity): a fit past the scene's largest N is a row that says
so, never a silent gap, and a field too slow for its timed rollouts is timed by its measured rollout, marked."""
import torch

from hnn_analysis.scenes import bodies_study as bodies

EPS = torch.finfo(torch.float64).eps


def test_a_fit_past_its_largest_n_is_a_row_and_a_slow_step_is_timed_by_its_rollout(monkeypatch):
    monkeypatch.setattr(bodies, "TIMING_BUDGET", 0.0)      # every field "slow": each timed by its own rollout
    results = bodies.study(sizes=(8, 70), fits=("library", "swim"), seed=0, starts=1, dt=0.01, horizon=0.03,
                           adam_steps=0, hidden=8, scene="gravity", largest={"swim": 8})
    small, large = results["rows"]
    assert "not_run" not in small["swim"] and large["swim"]["seconds_per_step"] is None
    assert large["swim"]["not_run"].startswith("past N = 8: ")
    # the library's softened term is gravity's V: its path is the true forces' to round-off, at 8 and at 70 bodies.
    # The two fields' arithmetic differs by a few eps a pull (64 eps of up to 69 pulls of at most 1 / 0.1^2): over 3
    # steps of 0.01 a momentum moves by 3 x 0.01 x 69 x 100 x 64 eps = 3e-12, and H per body by that times |p| (< 10)
    for row in results["rows"]:
        assert row["library"]["timed"] == row["true"]["timed"] == "rollout"
        assert abs(row["library"]["energy_per_body"] - row["true"]["energy_per_body"]) <= 10 * 3 * 0.01 * 69 * 100 * \
            64 * EPS
    results["meta"] = {"command": "python analysis/bodies.py --scene gravity", "cores": 2, "cpu": "test"}
    text = bodies.table(results)
    assert f"| 70 | not run: past N = 8: {bodies.SCENES['gravity']['largest_why']} |" in text
    assert "\\* timed by the rollout measured above" in text and "*|" in text.replace(" ", "")
