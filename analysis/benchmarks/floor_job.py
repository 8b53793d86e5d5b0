"""The benchmark's floor job and what the other jobs share: one training step of the spring HNN and of
the pixel HNN (at the paper's settings) timed against the matrix products it performs (``floor``),
at 1 and 2 threads; the pixel loss and its gradients checked against the original's formulation."""
from __future__ import annotations

import numpy as np
import torch

import hnn
from hnn.models import PixelHNN
from hnn.objectives import pixel_loss
from hnn.trainers.loop import adam_optimizer, optimizer_step
from hnn.trainers.rows import minibatch
from hnn.threads import torch_threads
from hnn.training import l2_loss
from hnn_analysis.benchmarks import floor

HIDDEN = 200
LEARN_RATE = 1e-3
WEIGHT_DECAY = 1e-4
# the pixel loss and its gradients on one batch: our tanh (2 sigmoid(2a) - 1) differs from torch's by
# up to 1.8e-7, and float32 sums in another order; measured 1e-6 or less
PIXEL_REL_TOL = 1e-4


def check(name: str, value: float, tolerance: float, detail: dict | None = None) -> dict:
    """A named check of ``value`` against ``tolerance`` (passed when finite and within it), as the JSON records it."""
    ok = bool(np.isfinite(value) and value <= tolerance)
    return {"name": name, "value": float(value), "tolerance": tolerance, "passed": ok, **(detail or {})}


def rel_diff(a: float, b: float) -> float:
    """|a - b| relative to the larger of the two."""
    return abs(a - b) / max(abs(a), abs(b), 1e-300)


PIXEL_ROWS, PIXEL_BATCH, PIXEL_SIDE = 16000, 200, 28
FLOOR_THREADS = (1, 2)


def spring_step(d: dict):
    """One step of ``hnn.train`` on the spring HNN: full batch, the closed-form field, fused Adam."""
    torch.manual_seed(0)
    model = hnn.build_model(2, HIDDEN)
    x, y = (torch.tensor(d[k], dtype=torch.float32) for k in ("x", "dxdt"))
    optim = adam_optimizer(model, LEARN_RATE, WEIGHT_DECAY)
    loss = l2_loss(model.time_derivative)
    return lambda: optimizer_step(loss, x, y, optim)


def pixel_step():
    """One step of ``hnn.train`` on the pixel HNN at the paper's settings (batch 200 of 16000 pairs,
    weight decay 1e-5). The frames are uniform noise, not renders: dense products and elementwise
    passes cost the same whatever the pixels hold, and rendering takes a minute."""
    torch.manual_seed(0)
    model = PixelHNN(2 * PIXEL_SIDE ** 2, 2, HIDDEN)
    gen = torch.Generator().manual_seed(0)
    frames = torch.rand(PIXEL_ROWS + 1, 2 * PIXEL_SIDE ** 2, generator=gen)
    x, x_next = frames[:-1], frames[1:]
    optim = adam_optimizer(model, LEARN_RATE, 1e-5)

    def step():
        xb, yb = minibatch(x, x_next, PIXEL_BATCH, gen)
        return optimizer_step(lambda a, b: pixel_loss(model, a, b), xb, yb, optim)
    return step


def original_pixel_loss(model: PixelHNN, x: torch.Tensor, x_next: torch.Tensor) -> torch.Tensor:
    """``PixelHNN.loss`` written the original's way on the same parameters: ``pow(2)`` for the
    reconstruction, the latent field by autograd through ``torch.tanh``."""
    z, z_next = model.encode(torch.cat([x, x_next])).split(len(x))
    ae = (x - model.decode(z)).pow(2).mean(dim=1)
    net = model.hnn.differentiable_model
    F = net.linear3(torch.tanh(net.linear2(torch.tanh(net.linear1(z)))))
    step = torch.autograd.grad(F[:, 1].sum(), z, create_graph=True)[0] @ model.hnn.M.T
    hnn_term = (z_next - (z + step)).pow(2).mean(dim=1)
    cc = (z[:, 1:] - (z_next[:, :1] - z[:, :1])).pow(2).mean(dim=1)
    return ae + cc + 0.1 * hnn_term


def pixelcheck() -> dict:
    """The pixel loss and every parameter's gradient, ours against ``original_pixel_loss``, on one batch."""
    torch.manual_seed(0)
    model = PixelHNN(2 * PIXEL_SIDE ** 2, 2, HIDDEN)
    gen = torch.Generator().manual_seed(1)
    x, x_next = (torch.rand(PIXEL_BATCH, 2 * PIXEL_SIDE ** 2, generator=gen) for _ in range(2))
    params = list(model.parameters())
    ours, theirs = pixel_loss(model, x, x_next).mean(), original_pixel_loss(model, x, x_next).mean()
    g_ours, g_theirs = torch.autograd.grad(ours, params), torch.autograd.grad(theirs, params)
    worst = max(float((a - b).norm() / b.norm().clamp(min=1e-30)) for a, b in zip(g_ours, g_theirs))
    return check("pixel loss and gradients vs the original's formulation, worst relative difference",
                  max(rel_diff(ours.item(), theirs.item()), worst), PIXEL_REL_TOL,
                  {"loss_ours": ours.item(), "loss_original": theirs.item(), "worst_gradient": worst})


def job_floor(d: dict, rounds: int) -> dict:
    """Each step against its matrix-product floor, at 1 and then 2 threads in this process
    (``hnn.threads.torch_threads``), with denormals flushed as ``hnn.train`` does."""
    steps = {"spring": (spring_step(d), rounds), "pixels": (pixel_step(), max(10, rounds // 4))}
    flushing = hnn.trainers.loop.flushes_denormals()
    torch.set_flush_denormal(True)
    out = {}
    try:
        for name, (step, n) in steps.items():
            shapes = floor.products(step)
            out[name] = {"products": floor.describe_products(shapes), "by_threads": {}}
            for t in FLOOR_THREADS:
                with torch_threads(t):      # this count, the caller's back after
                    out[name]["by_threads"][str(t)] = floor.compare(step, shapes, rounds=n, warmup=max(5, n // 5),
                                                                    block=max(2, n // 20))
                r = out[name]["by_threads"][str(t)]
                print(f"floor {name}, {t} thread(s): step {r['step_ms']:.2f} ms, floor {r['floor_ms']:.2f} ms, "
                      f"ratio {r['ratio']:.2f} (fastest rounds {r['best_ratio']:.2f})", flush=True)
    finally:
        torch.set_flush_denormal(flushing)
    out["checks"] = [pixelcheck()]
    return out


def floor_table(result: dict) -> str:
    lines = ["| training step | its matrix products | threads | products alone (ms) | step (ms) | step / floor "
             "| fastest rounds: step / floor |",
             "| --- | --- | ---: | ---: | ---: | ---: | ---: |"]
    labels = {"spring": f"spring HNN, 750 x 2, {HIDDEN} hidden",
              "pixels": f"pixel HNN, batch {PIXEL_BATCH}, {2 * PIXEL_SIDE ** 2} pixels"}
    for name, r in ((k, v) for k, v in result.items() if k in labels):
        for t, c in r["by_threads"].items():
            lines.append(f"| {labels[name]} | {r['products']} ({c['gflop']:.2f} GFLOP) | {t} | {c['floor_ms']:.2f} | "
                         f"{c['step_ms']:.2f} | {c['ratio']:.2f}x | {c['best_ratio']:.2f}x |")
    return "\n".join(lines)
