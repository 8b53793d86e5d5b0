"""The Sampling-HNNs protocols (Rahma, Datar & Dietrich 2024; AlphaGergedan/Sampling-HNNs) as a library:
their systems and domains, their published per-seed numbers, our sampled fit of each seed (``fit_one``)
and our Adam HNN on the same data (``adam_one``), and the tables (``markdown``).
``analysis/fits/sampling_hnns.py`` is its command.

Read from their code (src/single_pendulum_experiment.py, src/double_pendulum_experiment.py,
src/data/dataloader.py, src/trainer/sampler.py, swimnetworks' dense.py):
- data: states uniform in a box (test states distinct from the training ones), exact dx/dt = J grad H,
  and H(0) known, which fixes the constant of the learned H;
- the network: one hidden layer of tanh neurons, the last layer by numpy's ``lstsq`` (SVD) at rcond 1e-13,
  float64; ELM: w ~ N(0, I), b ~ U[min, max] of the box; SWIM: a neuron from a pair of training points,
  -1/2 at one and +1/2 at the other; pairs uniform (their U-SWIM), or drawn by |H(b) - H(a)| / |b - a|
  with the *true* H at the training points (their SWIM), or with a first fit's H (their A-SWIM, two fits);
- the metric: the relative L2 error of H on the test states, sqrt(sum (H - H_hat)^2 / sum H^2);
- 10 seeds (data seeds 3943.., model seeds 992472..), 64 threads, wall time of the sampling and solve.
Ours: the same boxes, sizes, widths, rcond and metric, our own seeded draws (``numpy.random.default_rng``:
seed s draws the data with 3943 + s and the neurons with s), our QR solve (``hnn.fits``) on this box.
"""
from __future__ import annotations

import math
import resource
from dataclasses import dataclass

import numpy as np
import torch

import hnn
from hnn.threads import torch_threads
from hnn_analysis.pages import generated_by


@dataclass(frozen=True)
class Protocol:
    """One of their experiments: ``dof`` degrees of freedom, q and p uniform in ``q`` and ``p`` per
    coordinate, ``train`` and ``test`` states, the ``widths`` we reproduce."""
    name: str
    dof: int
    q: tuple[float, float]
    p: tuple[float, float]
    train: int
    test: int
    widths: tuple[int, ...]

    def hamiltonian(self, x: torch.Tensor) -> torch.Tensor:
        """H (rows,) at x = [q, p] (rows, 2 dof), m = l = g = 1."""
        if self.dof == 1:
            q, p = x[:, 0], x[:, 1]
            return p ** 2 / 2 + 1 - torch.cos(q)
        q1, q2, p1, p2 = x.unbind(1)
        s = torch.sin(q1 - q2)
        return (p1 ** 2 + 2 * p2 ** 2 - 2 * p1 * p2 * torch.cos(q1 - q2)) / (2 * (1 + s ** 2)) \
            - 2 * torch.cos(q1) - torch.cos(q2)


PROTOCOLS = {
    "single": Protocol("single pendulum", 1, (-2 * math.pi, 2 * math.pi), (-1.0, 1.0), 10000, 10000, (1000,)),
    "double": Protocol("double pendulum", 2, (-math.pi, math.pi), (-1.0, 1.0), 20000, 20000, (5000, 10000)),
}
RCOND = 1e-13          # their lstsq rcond, our ridge relative to unit columns
DATA_SEED = 3943        # their first data seed; seed s of ours draws the data with DATA_SEED + s
# their per-seed files (10 seeds each; mean, standard deviation ddof 1, mean seconds on 64 threads):
# experiments/single-pendulum/small_domain_experiment_hidden_1000.pkl,
# experiments/double-pendulum/experiment_hidden_{5000,10000}.pkl
PUBLISHED = {
    ("single", 1000): {"elm": (1.493e-11, 9.17e-12, 2.0), "uswim": (8.738e-10, 2.75e-10, 1.8),
                       "aswim": (3.620e-10, 9.50e-11, 4.1), "swim": (3.620e-10, 9.50e-11, 1.8)},
    ("double", 5000): {"elm": (5.687e-3, 4.63e-4, 43.1), "uswim": (5.001e-3, 5.24e-4, 39.6),
                       "aswim": (4.083e-3, 5.11e-4, 85.2), "swim": (4.183e-3, 4.07e-4, 40.0)},
    ("double", 10000): {"elm": (2.517e-3, 5.23e-4, 138.5), "uswim": (3.009e-3, 2.42e-4, 120.7),
                        "aswim": (2.572e-3, 2.27e-4, 253.6), "swim": (2.660e-3, 2.95e-4, 121.9)},
}
# their Adam-trained HNN (experiments/double-pendulum-hnn-on-cpu/out.txt): one hidden layer of 5000 tanh
# neurons, float64, batch 2048, lr 1e-4, 180000 steps on 64 threads, one seed
PUBLISHED_ADAM = {"double": {"error": 3.62e-3, "seconds": 10485.4, "width": 5000, "steps": 180000}}
# our variants: how the pairs are drawn (theirs: U-SWIM, SWIM with the true H, ELM)


def default_variants(width: int) -> tuple[str, ...]:
    """The variants a width runs by default: all three up to 1000 (seconds), uniform pairs and SWIM up to 5000
    (a minute a fit on 2 cores), uniform pairs alone beyond (dx/dt's own variant; minutes a fit)."""
    return ("uswim", "swim", "elm") if width <= 1000 else ("uswim", "swim") if width <= 5000 else ("uswim",)


VARIANTS = {"uswim": "uniform pairs: dx/dt alone (fit swim)", "swim": "pairs by the true H at the training "
            "points (their SWIM; needs H values a dataset of dx/dt does not have)", "elm": "random weights (fit elm)"}


def dataset(protocol: Protocol, seed: int) -> dict:
    """``x``, ``dxdt``, ``H`` (training) and ``test_x``, ``test_H``: uniform in the box, test states apart from
    the training ones, exact dx/dt = J grad H (autograd of ``hamiltonian``), float64."""
    rng = np.random.default_rng(DATA_SEED + seed)
    n = protocol.dof

    def box(rows: int) -> np.ndarray:
        return np.column_stack([rng.uniform(*protocol.q, rows) for _ in range(n)]
                               + [rng.uniform(*protocol.p, rows) for _ in range(n)])
    x, test = box(protocol.train), box(protocol.test)
    xt = torch.as_tensor(x).requires_grad_(True)
    grad = torch.autograd.grad(protocol.hamiltonian(xt).sum(), xt)[0].numpy()
    with torch.no_grad():
        h, test_h = (protocol.hamiltonian(torch.as_tensor(a)).numpy() for a in (x, test))
    return {"x": x, "dxdt": np.concatenate([grad[:, n:], -grad[:, :n]], axis=1), "H": h, "test_x": test,
            "test_H": test_h}


def relative_error(model, data: dict) -> float:
    """sqrt(sum (H - H_hat)^2 / sum H^2) on the test states."""
    with torch.no_grad():
        h_hat = model.hamiltonian(torch.as_tensor(data["test_x"])).numpy()
    return float(np.sqrt(((h_hat - data["test_H"]) ** 2).sum() / (data["test_H"] ** 2).sum()))


def anchor(protocol: Protocol) -> tuple:
    """``(x0, H(x0))`` at x0 = 0: the one H value their protocol knows, which fixes a learned H's constant."""
    zero = torch.zeros(1, 2 * protocol.dof, dtype=torch.float64)
    return zero[0].numpy(), float(protocol.hamiltonian(zero))


def fit_one(name: str, width: int, variant: str, seed: int, threads: int) -> dict:
    """One seed of our sampled fit: ``{"error", "seconds", "peak_gib"}`` (``peak_gib``: this process's
    peak resident memory so far; the command runs each width in a fresh process)."""
    protocol = PROTOCOLS[name]
    data = dataset(protocol, seed)
    with torch_threads(threads):        # the count measured, the caller's back after
        model, stats = hnn.fit_least_squares("hnn", data["x"], data["dxdt"], fit="elm" if variant == "elm" else "swim",
                                             width=width, seed=seed, rcond=RCOND, anchor=anchor(protocol),
                                             values=data["H"] if variant == "swim" else None, progress=False)
    return {"error": relative_error(model, data), "seconds": stats["seconds"],
            "peak_gib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2 ** 20}


def adam_one(name: str, seed: int, threads: int, steps: int, width: int = 200, batch: int = 2048) -> dict:
    """One seed of our Adam HNN (the paper's MLP, ``width`` x 2 tanh, float64 as theirs) on the same data:
    ``steps`` Adam steps of minibatches of ``batch``, the learned H anchored at H(0) as theirs."""
    protocol = PROTOCOLS[name]
    data = dataset(protocol, seed)
    # at ``threads`` threads (the loop at hnn.train's one), the caller's count and random state back after
    with torch_threads(threads):
        with hnn.policy.seeded(seed):       # the init drawn from the seed
            model = hnn.build_model(2 * protocol.dof, width).double()
        stats = hnn.train(model, data["x"], data["dxdt"], total_steps=steps, batch_size=batch, seed=seed,
                          print_every=10 ** 9, progress=False)
        zero, h0 = anchor(protocol)
        with torch.no_grad():
            offset = h0 - float(model.hamiltonian(torch.as_tensor(zero)[None]))

        class Anchored:
            def hamiltonian(self, x):
                return model.hamiltonian(x) + offset
        return {"error": relative_error(Anchored(), data), "seconds": stats["seconds"], "steps": steps}


def summary(values: list[float]) -> tuple[float, float]:
    """(mean, standard deviation ddof 1; 0 for one value)."""
    v = np.asarray(values, dtype=np.float64)
    return float(v.mean()), float(v.std(ddof=1)) if len(v) > 1 else 0.0


def verdict(ours: tuple[float, float], theirs: tuple) -> str:
    """Our mean against theirs: ``'within'`` their mean +- 2 sd, ``'better'`` below it, ``'worse'`` above."""
    if abs(ours[0] - theirs[0]) <= 2 * theirs[1]:
        return "within"
    return "better" if ours[0] < theirs[0] else "worse"


def _seconds(row: dict) -> str:
    """A row's median seconds and the range of its seeds' (the box's other load moves single timings)."""
    each = [r["seconds"] for r in row["per_seed"]]
    return f"{row['seconds']:.3g}" + (f" ({min(each):.3g}-{max(each):.3g})" if len(each) > 1 else "")


def markdown(results: dict) -> str:
    """The table of every protocol and width: ours per variant (mean +- sd over seeds, seconds, peak memory)
    beside theirs, and the Adam HNNs."""
    meta = results["meta"]
    lines = [generated_by(meta, f"torch {meta['torch']}, {meta['cores']} cores, {meta['cpu']}; {meta['threads']} torch "
                                f"threads; seeds {meta['seeds']}") + ".", "",
             "| system | width | pairs | ours: relative H error (mean ± sd) | against theirs ± 2 sd | ours: s "
             "(median; range) | peak GiB | theirs: error (10 seeds) | theirs: s (64 threads) |",
             "| --- | ---: | --- | --- | --- | ---: | ---: | --- | ---: |"]
    for row in results["rows"]:
        theirs = PUBLISHED[(row["protocol"], row["width"])][row["variant"]]
        ours = row["error"]
        lines.append(f"| {PROTOCOLS[row['protocol']].name} | {row['width']} | {row['variant']} | "
                     f"{ours[0]:.3g} ± {ours[1]:.2g} | {verdict(ours, theirs)} | "
                     f"{_seconds(row)} | {row['peak_gib']:.2g} | {theirs[0]:.3g} ± {theirs[1]:.2g} | {theirs[2]:.3g} |")
    for row in results.get("adam", []):
        pub = PUBLISHED_ADAM.get(row["protocol"], {})
        lines.append(f"| {PROTOCOLS[row['protocol']].name} | 200 x 2 | Adam, {row['steps']} steps | "
                     f"{row['error'][0]:.3g} ± {row['error'][1]:.2g} | | {_seconds(row)} | | "
                     + (f"Adam, width {pub['width']}, {pub['steps']} steps: {pub['error']:.3g} (1 seed) | "
                        f"{pub['seconds']:.0f} |" if pub else " | |"))
    lines += ["", "Pairs: uswim, uniform pairs of training states (dx/dt alone: `--fit swim`); swim, pairs drawn by "
              "the true H at the training states (their SWIM); elm, random weights. Seconds: the sampling and the "
              f"solve on {meta['threads']} thread(s) of this box (another process's load beside it: median "
              f"{results.get('others_median', 0):.2g} cores), theirs on 64; peak GiB: the resident memory of the "
              "process that fitted the width. Against theirs: our mean within their mean ± 2 sd (sd over their 10 "
              "seeds), better below it, worse above."]
    return "\n".join(lines) + "\n"
