"""The "bring your own system" example of docs/python.md, run as written, then checked physically."""
import re

import numpy as np
import torch

import hnn

PAGE = hnn.tasks.repo_root() / "docs" / "python.md"


def _readme_example() -> str:
    text = PAGE.read_text()
    match = re.search(r"<!-- example: custom-system -->\s*```python\n(.*?)```", text, re.S)
    assert match, f"{PAGE} lost its custom-system example"
    return match.group(1)


def test_readme_custom_system_example_learns_and_conserves_the_true_energy():
    scope = {}
    exec(compile(_readme_example(), "docs/python.md:custom-system", "exec"), scope)
    H, field, x, dxdt, model, x0, t_eval, traj = (scope[k] for k in
                                                  ("H", "field", "x", "dxdt", "model", "x0", "t_eval", "traj"))
    assert traj.shape == (2, len(t_eval), 2)
    # the learned field matches the true one on the held-out states (relative RMS)
    with torch.no_grad():
        err = (model.time_derivative(x[800:].double()) - dxdt[800:].double()).pow(2).mean().sqrt()
    assert float(err / dxdt[800:].pow(2).mean().sqrt()) < 0.05, float(err)
    # the HNN's rollout keeps the true H; a baseline trained identically drifts more
    torch.manual_seed(0)
    baseline = hnn.HNN(2, hnn.MLP(2, 200, 2), baseline=True)
    hnn.train(baseline, x[:800], dxdt[:800], x[800:], dxdt[800:], total_steps=500, weight_decay=0.0)
    with torch.no_grad():
        base_traj = hnn.rollout(baseline.double().time_derivative, x0, t_eval, method="rk4", dt=0.05)
    drift = (H(traj.reshape(-1, 2)).reshape(2, -1) - H(x0)[:, None]).abs().max()
    base_drift = (H(base_traj.reshape(-1, 2)).reshape(2, -1) - H(x0)[:, None]).abs().max()
    assert float(drift) < 0.02 * float(H(x0).min()), float(drift)
    assert float(drift) < float(base_drift), (float(drift), float(base_drift))
    # the model's own H is conserved by the midpoint rule far better than the true one
    learned = model.hamiltonian(traj.reshape(-1, 2)).reshape(2, -1).detach()
    assert float((learned - learned[:, :1]).abs().max()) < 1e-3
    assert np.isfinite(traj.numpy()).all()


def test_the_readme_snippet_runs_and_prints_the_drift_it_computes(capsys):
    """The README's "Use it from Python" snippet, as written but for fewer training steps (speed):
    it prints the learned energy's drift along its midpoint path, which stays small (symplectic)."""
    text = (hnn.tasks.repo_root() / "README.md").read_text()
    match = re.search(r"## Use it from Python\s*```python\n(.*?)```", text, re.S)
    assert match, "the README lost its Python snippet"
    code = match.group(1).replace("total_steps=2000", "total_steps=200")
    scope = {}
    exec(compile(code, "README.md:python", "exec"), scope)
    printed = capsys.readouterr().out.strip().splitlines()[-1]
    torch.manual_seed(12345)            # whatever ran before: the snippet seeds itself, so a reader sees this number
    exec(compile(code, "README.md:python", "exec"), {})
    assert capsys.readouterr().out.strip().splitlines()[-1] == printed
    assert printed.startswith("learned energy drift along the path: ")
    drift = float(printed.rsplit(" ", 1)[1])
    H = scope["H"].detach()
    assert drift == float(f"{(H.max() - H.min()).item():.2e}")
    assert drift < 1e-2 * H.abs().mean().item()
