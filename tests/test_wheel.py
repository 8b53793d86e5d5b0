"""`pip install .` builds a wheel that works without the checkout: from the wheel alone (unpacked into an
empty folder, run from elsewhere), `import hnn`, a model, `hnn.train`, `hnn.rollout` and a run folder
through `hnn.run_experiment` and `hnn.load_run` give the numbers the checkout gives, and the tasks, which
live in the checkout, are refused with one line saying so."""
import importlib.util
import json
import os
import re
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path


import hnn

REPO = hnn.tasks.repo_root()

SCRIPT = r'''
import json, math, sys, tempfile
from dataclasses import dataclass
import numpy as np, torch, hnn

out = {"file": hnn.__file__}
torch.manual_seed(0)
rng = np.random.default_rng(0)
x = torch.tensor(rng.uniform(-1, 1, (200, 2)), dtype=torch.float32)
dxdt = torch.stack([x[:, 1], -x[:, 0]], dim=1)                 # the spring H = (q^2 + p^2) / 2
model = hnn.HNN(2, hnn.MLP(2, 32, 2))
stats = hnn.train(model, x, dxdt, x, dxdt, total_steps=150, progress=False)
out["losses"] = [float(v) for v in stats["train_loss"][::50]]
t = np.linspace(0, 2 * math.pi, 65)
truth = hnn.rollout(lambda s: torch.stack([s[:, 1], -s[:, 0]], 1), torch.tensor([[1.0, 0.0]], dtype=torch.float64),
                    t, method="rk4", dt=0.01)
out["rk4_error"] = float((truth[0, :, 0] - torch.tensor(np.cos(t))).abs().max())


@dataclass
class Spring(hnn.RunConfig):
    name: str = "spring-from-a-wheel"
    hidden_dim: int = 16
    total_steps: int = 20

    def dataset(self):
        return {"x": x.numpy(), "dxdt": dxdt.numpy(), "test_x": x.numpy(), "test_dxdt": dxdt.numpy()}


run = hnn.run_experiment(Spring(save_dir=tempfile.mkdtemp()))
out["run_test_loss"] = hnn.load_run(run)[2]["test_loss"]
try:
    hnn.available_tasks()
except FileNotFoundError as err:
    out["tasks"] = str(err)
print(json.dumps(out))
'''


def _run(tmp_path: Path, pythonpath: str | None) -> dict:
    env = {k: v for k, v in os.environ.items() if k not in ("HNN_REPO", "PYTHONPATH")}
    env.update(OMP_NUM_THREADS="1", **({"PYTHONPATH": pythonpath} if pythonpath else {}))
    done = subprocess.run([sys.executable, "-c", SCRIPT], cwd=tmp_path, env=env, capture_output=True, text=True,
                          timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_the_wheel_alone_imports_trains_rolls_out_and_saves_runs_as_the_checkout_does(tmp_path):
    # build from a copy of what the wheel is made of, so nothing is written into the checkout
    src = tmp_path / "src"
    for name in ("hnn", "analysis"):
        shutil.copytree(REPO / name, src / name, ignore=shutil.ignore_patterns("__pycache__"))
    for name in ("pyproject.toml", "README.md"):
        shutil.copy(REPO / name, src / name)
    # build with the environment's setuptools where it can make a wheel (setuptools >= 70.1, or the wheel
    # package beside it); otherwise pip fetches a build backend into an isolated environment
    can_build = importlib.util.find_spec("setuptools") is not None and (
        importlib.util.find_spec("wheel") is not None or importlib.util.find_spec("setuptools.command.bdist_wheel"))
    isolation = ["--no-build-isolation"] if can_build else []
    built = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", *isolation, "-w",
                            str(tmp_path / "dist"), str(src)], capture_output=True, text=True, timeout=600)
    assert built.returncode == 0, built.stderr[-3000:]
    [wheel] = (tmp_path / "dist").glob("*.whl")
    name = re.search(r'^name = "([^"]+)"', (REPO / "pyproject.toml").read_text(), re.M).group(1)
    assert name != "hnn" and wheel.name.startswith(name.replace("-", "_") + "-"), wheel.name   # not PyPI's "hnn"
    site = tmp_path / "site"
    with zipfile.ZipFile(wheel) as archive:       # a pure-Python wheel installs by unpacking
        archive.extractall(site)
        assert not [n for n in archive.namelist() if n.startswith(("experiment-", "tests/"))]
    (tmp_path / "elsewhere").mkdir()
    alone = _run(tmp_path / "elsewhere", str(site))
    assert Path(alone["file"]).is_relative_to(site)
    # the checkout under test by its path: the installed `hnn` may be another checkout's editable install (a
    # clone tested beside the developer's own, as quick_budgets.py does)
    checkout = _run(tmp_path / "elsewhere", str(REPO))
    assert Path(checkout["file"]).is_relative_to(REPO)
    for key in ("losses", "rk4_error", "run_test_loss"):
        assert alone[key] == checkout[key], key          # the same code: the same bits at one thread
    assert alone["losses"][-1] < 0.1 * alone["losses"][0]       # it learns the spring's field
    assert alone["rk4_error"] < 1e-8                            # RK4 at h = 0.01 over one period: ~h^4
    assert "the tasks live in the repository" in alone["tasks"]
