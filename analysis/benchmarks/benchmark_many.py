"""Many models at once, on every device present: model-steps per second of K paper-sized spring HNNs.

    python analysis/benchmarks/benchmark_many.py                       # K = 1, 16, 128 on the CPU; 1 .. 1024 on a GPU
    python analysis/benchmarks/benchmark_many.py --sizes 1 16 --steps 5 # smaller
    python analysis/benchmarks/benchmark_many.py --update-docs          # docs/speed.md (CPU), docs/gpu.md (GPU)

K HNNs of the paper's spring shape (2-200-200-1 tanh, the seed-0 dataset's 750 rows as one full
batch, Adam at lr 1e-3 and weight decay 1e-4), each step timed four ways in one process:

- ``anchor``: the plain batched step, written here in a few lines: weights stacked along a model
  axis, the forward by ``baddbmm``/``bmm``, the symplectic gradient by ``torch.autograd.grad`` with
  ``create_graph``, one fused Adam over the stacks. The yardstick a group must reach.
- ``group``: ``hnn.grouped.fit_group`` (the tanh MLP's closed-form input gradient and its
  hand-written backward, batched over the model axis): no double backward.
- ``stacked``: ``hnn.stacked.fit_stacked`` on the same models (``torch.func.vmap`` over the model
  axis, ``torch.func.grad`` for the input gradient): the path every other kind takes.
- ``lone``: ``hnn.train`` on one model after another (K = 1 and 16 only; its rate does not depend on K).

Each cell is the median over ``--repeats`` of (wall time of ``--steps`` steps) after one warm-up
call; model-steps per second = K x steps / seconds. The table says the device, torch version and
thread count.
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import torch

import hnn
from hnn import grouped, stacked
from hnn.training import fit_loss
from hnn_analysis import commands
from hnn_analysis.provenance import machine, provenance

WIDTH, ROWS_NOTE = 200, "750 x 2 full batch"
CPU_SIZES, GPU_SIZES = (1, 16, 128), (1, 16, 128, 1024)
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
    return _fit_seconds(grouped.fit_group, k, data, steps, device)


def stacked_seconds(k, data, steps, device) -> float:
    return _fit_seconds(lambda *a, **kw: stacked.fit_stacked(*a, loss_of=fit_loss, **kw), k, data, steps, device)


def lone_seconds(k, data, steps, device) -> float:
    models = _models(min(k, LONE_MAX), device)
    _sync(device)
    tic = time.perf_counter()
    for seed, model in enumerate(models):
        hnn.train(model, data["x"], data["dxdt"], total_steps=steps - 1, seed=seed, progress=False)
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


def table(rows: list[dict], meta: dict) -> str:
    device = rows[0]["device"] if rows else "?"
    where = meta.get("gpu") or machine(meta)
    lines = [f"From `{meta['command']}` at commit {meta.get('commit', '?')} on {device} ({where}, torch "
             f"{meta['torch']}, {meta['threads']} thread(s)): K spring HNNs 2-{WIDTH}-{WIDTH}-1 tanh, {ROWS_NOTE}, "
             f"Adam; model-steps per second, median of {meta['repeats']} x {rows[0]['steps'] if rows else 0} steps. "
             "anchor: the plain batched `bmm` step with autograd's double backward; group: `hnn.grouped.fit_group` "
             "(closed form); stacked: `hnn.stacked.fit_stacked` (vmap, every kind's path); lone: one model after "
             "another.", "",
             "| K | anchor | group | stacked | lone | group / anchor | group / lone |",
             "| ---: | ---: | ---: | ---: | ---: | ---: | ---: |"]
    for r in rows:
        lone = f"{r['lone']:.0f}" if "lone" in r else "-"
        per_lone = f"{r['group'] / r['lone']:.2f}x" if "lone" in r else "-"
        lines.append(f"| {r['models']} | {r['anchor']:.0f} | {r['group']:.0f} | {r['stacked']:.0f} | {lone} | "
                     f"{r['group'] / r['anchor']:.2f}x | {per_lone} |")
    return "\n".join(lines)


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=None,
                        help=f"group sizes K (default: {CPU_SIZES} on the CPU, {GPU_SIZES} on a GPU)")
    parser.add_argument("--steps", type=int, default=10, help="steps a timed call (default 10)")
    parser.add_argument("--repeats", type=int, default=3, help="timed calls a cell (default 3)")
    parser.add_argument("--devices", nargs="+", default=None, help="torch devices (default: cpu and cuda if present)")
    commands.add_flags(parser, out="folder for many_models.json and .md", out_default=Path("results-bench"),
                       update_docs="write the CPU table into docs/speed.md and a GPU's into docs/gpu.md")
    args = parser.parse_args(argv)
    devices = args.devices or ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])
    meta = {**provenance(), "repeats": args.repeats,
            "command": commands.portable_command(sys.argv[1:] if argv is None else list(argv),
                                                 "analysis/benchmarks/benchmark_many.py")}
    results, texts, sections = {"meta": meta, "rows": {}}, [], {}
    for name in devices:
        device = torch.device(name)
        sizes = args.sizes or (CPU_SIZES if device.type == "cpu" else GPU_SIZES)
        rows = measure(device, sizes, args.steps, args.repeats)
        here = {**meta, "gpu": torch.cuda.get_device_name(device) if device.type == "cuda" else None}
        results["rows"][name] = rows
        texts.append(table(rows, here))
        if args.update_docs:
            sections["many-models" if device.type == "cpu" else "many-models-gpu"] = texts[-1]
    commands.publish(args.out, "many_models", results, "\n\n".join(texts) + "\n", sections)
    return results


if __name__ == "__main__":
    main()
