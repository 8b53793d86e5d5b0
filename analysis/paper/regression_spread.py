"""How far training's last bits move the spring regression numbers: the spread behind the
thresholds of ``tests/test_regression.py``.

    python analysis/paper/regression_spread.py                         # seeds 0-4, threads 1 and 2, this CPU's kernels
    python analysis/paper/regression_spread.py --kernels default avx2  # also torch's AVX2 kernels on an AVX-512 CPU

Each configuration (threads x kernels) runs in its own process, because the thread count and
``ATEN_CPU_CAPABILITY`` must be set before torch is imported; configurations run one at a time
(two torch processes side by side on two cores slow each other down many times over). Every
process trains the spring baseline and HNN at each seed with the task's default flags and
evaluates the energy MSE under both protocols. Prints a table and the extremes, and writes
``<out>/regression_spread.json``.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import hnn

KINDS = ("baseline", "hnn")
PROTOCOLS = ("paper", "corrected")


def _measure(seeds: list[int], steps: int | None) -> list[dict]:
    """In this process: train and evaluate the spring models at every seed."""
    import hnn

    trainer, spring = hnn.load_task("spring", "train"), hnn.load_task("spring")
    rows = []
    with tempfile.TemporaryDirectory() as out:
        for seed in seeds:
            extra = [] if steps is None else ["--total_steps", str(steps)]
            runs = {kind: trainer.main(["--save_dir", out, "--seed", str(seed)] + extra
                                       + (["--baseline"] if kind == "baseline" else [])) for kind in KINDS}
            loaded = {kind: hnn.load_run(run) for kind, run in runs.items()}
            models = {kind: model for kind, (model, _, _) in loaded.items()}
            row = {"seed": seed}
            for kind, (_, _, metrics) in loaded.items():
                row[f"{kind}_train_loss"], row[f"{kind}_test_loss"] = metrics["train_loss"], metrics["test_loss"]
            for protocol in PROTOCOLS:
                result = hnn.evaluate_energy(spring, models, hnn.tasks.get_protocol("spring", protocol))
                for kind in KINDS:
                    row[f"{kind}_energy_{protocol}"] = result[kind]["mse"]
                row[f"ratio_{protocol}"] = result["baseline"]["mse"] / result["hnn"]["mse"]
            rows.append(row)
    return rows


def _run_config(threads: int, kernels: str, seeds: list[int], steps: int | None) -> list[dict]:
    env = dict(os.environ, OMP_NUM_THREADS=str(threads), MKL_NUM_THREADS=str(threads))
    if kernels != "default":
        env["ATEN_CPU_CAPABILITY"] = kernels
    cmd = [sys.executable, __file__, "--_worker", "--seeds", *map(str, seeds)]
    if steps is not None:
        cmd += ["--steps", str(steps)]
    done = subprocess.run(cmd, env=env, capture_output=True, text=True, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def _table(rows: list[dict]) -> str:
    head = ("| threads | kernels | seed | base train | hnn train | base test | hnn test | ratio paper | "
            "ratio corrected |\n|---:|---|---:|---:|---:|---:|---:|---:|---:|")
    body = [f"| {r['threads']} | {r['kernels']} | {r['seed']} | {r['baseline_train_loss']:.4e} | "
            f"{r['hnn_train_loss']:.4e} | {r['baseline_test_loss']:.4e} | {r['hnn_test_loss']:.4e} | "
            f"{r['ratio_paper']:.0f}x | {r['ratio_corrected']:.0f}x |" for r in rows]
    return "\n".join([head] + body)


def main(argv=None) -> dict:
    p = hnn.cli.Parser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4], help="seeds to train")
    p.add_argument("--threads", type=int, nargs="+", default=[1, 2], help="thread counts to try")
    p.add_argument("--kernels", nargs="+", default=["default"],
                   help="ATEN_CPU_CAPABILITY values to try (default = what torch picks; e.g. avx2)")
    p.add_argument("--steps", type=int, default=None, help="training steps (default: the task's 2000)")
    p.add_argument("--out", type=Path, default=Path("results"), help="folder for regression_spread.json")
    p.add_argument("--_worker", action="store_true", help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args._worker:
        print(json.dumps(_measure(args.seeds, args.steps)))
        return {}
    rows = []
    for kernels in args.kernels:
        for threads in args.threads:
            for row in _run_config(threads, kernels, args.seeds, args.steps):
                rows.append({"threads": threads, "kernels": kernels, **row})
                print(_table(rows[-1:]).splitlines()[-1], flush=True)
    summary = {key: [min(r[key] for r in rows), max(r[key] for r in rows)]
               for key in rows[0] if key not in ("threads", "kernels", "seed")}
    print("\n" + _table(rows) + "\n\nrange over all rows:")
    for key, (lo, hi) in summary.items():
        print(f"  {key}: {lo:.4g} .. {hi:.4g}")
    result = {"rows": rows, "range": summary}
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "regression_spread.json").write_text(json.dumps(result, indent=2) + "\n")
    return result


if __name__ == "__main__":
    main()
