"""The bodies study (analysis/bodies.py): a pair model fitted on 8 bodies rolls out chains of other lengths. The
radial library recovers the lattice's spring exactly, so its paths at every N are the true forces' leapfrog
paths to round-off: the study's energy and rollout errors for it equal the true forces' to that precision."""
import pytest

from hnn_analysis.scenes import bodies_study as bodies


def test_the_exact_library_runs_zero_shot_as_the_true_forces_do():
    results = bodies.study(sizes=(8, 20), fits=("library",), seed=0, starts=2, dt=0.1, horizon=2.0,
                           adam_steps=0, hidden=8)
    assert [row["N"] for row in results["rows"]] == [8, 20]
    for row in results["rows"]:
        mine, true = row["library"], row["true"]
        # the leapfrog's own error (dt 0.1 over 2 time units) is far above round-off: the two paths agree to
        # the fit's coefficients, recovered to a few hundred eps (tests/test_lattice.py)
        assert mine["rollout"] == pytest.approx(true["rollout"], rel=1e-6)
        assert mine["energy_per_body"] == pytest.approx(true["energy_per_body"], rel=1e-6)
        assert true["rollout"] > 1e-6 and mine["seconds_per_step"] > 0
    assert "sum r^2" in results["fits"]["library"]["what"]
    results["meta"] = {"command": "python analysis/bodies.py --quick", "cores": 2, "cpu": "test"}
    text = bodies.table(results)
    assert "| 20 |" in text and "**library**" in text
