"""Many models at once, measured (``analysis/benchmarks/benchmark_many.py`` is its command, and its
docstring says what each way is): K spring HNNs stepped as the plain batched anchor, as a group
(``hnn.trainers.closed_form``), stacked (``hnn.trainers.vmap``) and one after another (``hnn.train``).
"""
from __future__ import annotations

import statistics
import time

import torch

import hnn
from hnn.trainers.closed_form import train_closed_form
from hnn.trainers.vmap import train_vmap
from hnn.training import dxdt_loss

WIDTH = 200
LONE_MAX = 16       # lone runs are timed up to this K (their rate does not depend on K)


def _sync(device: torch.device) -> None:
    if device.type == "cuda":
        torch.cuda.synchronize(device)


def _models(k: int, device: torch.device) -> list:
    out = []
    for seed in range(k):
        torch.manual_seed(seed)
        out.append(hnn.build_model(2, WIDTH).to(device))
    return out


def anchor_seconds(k: int, x: torch.Tensor, y: torch.Tensor, steps: int) -> float:
    """Seconds of ``steps`` plain batched steps of K HNNs on ``x``, ``y`` ``(rows, 2)`` (see the module)."""
    device, gen = x.device, torch.Generator("cpu").manual_seed(0)

    def stack(*shape):
        return (torch.randn(k, *shape, generator=gen) * shape[-1] ** -0.5).to(device).requires_grad_(True)
    W1, b1, W2, b2, W3 = stack(WIDTH, 2), stack(1, WIDTH), stack(WIDTH, WIDTH), stack(1, WIDTH), stack(2, WIDTH)
    weights = [W1, b1, W2, b2, W3]
    optim = torch.optim.Adam(weights, lr=1e-3, weight_decay=1e-4, fused=device.type in ("cpu", "cuda"))
    xs, ys = x.expand(k, -1, -1), y.expand(k, -1, -1)
    _sync(device)
    tic = time.perf_counter()
    for _ in range(steps):
        xin = xs.detach().requires_grad_(True)
        h = torch.tanh(torch.baddbmm(b1, xin, W1.mT))
        h = torch.tanh(torch.baddbmm(b2, h, W2.mT))
        out = torch.bmm(h, W3.mT)
        g = torch.autograd.grad(out[..., 1].sum(), xin, create_graph=True)[0]
        field = torch.cat([g[..., 1:], -g[..., :1]], dim=-1)
        loss = (field - ys).pow(2).mean(dim=(1, 2)).sum()
        loss.backward()
        optim.step()
        optim.zero_grad(set_to_none=True)
    _sync(device)
    return time.perf_counter() - tic


def _fit_seconds(fit, k: int, data: dict, steps: int, device: torch.device) -> float:
    models = _models(k, device)
    pairs = [(data["x"], data["dxdt"])] * k
    _sync(device)
    tic = time.perf_counter()
    fit(models, pairs, seeds=list(range(k)), total_steps=steps - 1)       # the loop runs total_steps + 1
    _sync(device)
    return time.perf_counter() - tic


def group_seconds(k, data, steps, device) -> float:
    return _fit_seconds(train_closed_form, k, data, steps, device)


def stacked_seconds(k, data, steps, device) -> float:
    return _fit_seconds(lambda *a, **kw: train_vmap(*a, loss_of=dxdt_loss, **kw), k, data, steps, device)


def lone_seconds(k, data, steps, device) -> float:
    models = _models(min(k, LONE_MAX), device)
    _sync(device)
    tic = time.perf_counter()
    for seed, model in enumerate(models):
        hnn.train(model, data["x"], data["dxdt"], total_steps=steps - 1, seed=seed, progress=False, threads=None)
    _sync(device)
    return (time.perf_counter() - tic) * k / len(models)


WAYS = {"anchor": None, "group": group_seconds, "stacked": stacked_seconds, "lone": lone_seconds}


def measure(device: torch.device, sizes, steps: int, repeats: int) -> list[dict]:
    data = hnn.load_task("spring").get_dataset(seed=0)
    x = torch.as_tensor(data["x"], device=device)
    y = torch.as_tensor(data["dxdt"], device=device)
    rows = []
    for k in sizes:
        row = {"device": str(device), "models": k, "steps": steps}
        for way, seconds_of in WAYS.items():
            if way == "lone" and k > LONE_MAX:
                continue
            run = (lambda n, k=k: anchor_seconds(k, x, y, n)) if way == "anchor" else \
                (lambda n, k=k, f=seconds_of: f(k, data, n, device))
            run(2)                           # first calls pay one-time setup (kernels, functorch)
            times = [run(steps) for _ in range(repeats)]
            row[way] = k * steps / statistics.median(times)
            row[f"{way}_step_ms"] = statistics.median(times) / steps * 1e3
            print(f"{device} K={k:5d} {way:8s} {row[way]:10.0f} model-steps/s ({row[f'{way}_step_ms']:.2f} ms a step)",
                  flush=True)
        rows.append(row)
    return rows
