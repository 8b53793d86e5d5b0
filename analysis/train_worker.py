"""One training run in its own process, for ``reproduce.py --jobs N`` (not meant to be run by hand).

    python analysis/train_worker.py --threads 1 --status STATUS.json --task spring -- --seed 0 ...

Sets the thread count before torch is imported (OMP_NUM_THREADS, MKL_NUM_THREADS, then
``torch.set_num_threads``), runs ``experiment-<task>/train.py``'s ``main(argv)``, and keeps
``STATUS.json`` (written atomically) up to date for the parent: ``{"step", "total"}`` while
training, at most every ``--every`` seconds, then ``{"done": true, "run": folder}`` or
``{"error": message, "type": exception class name}``.
"""
import argparse
import os
import sys
import time


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--threads", type=int, required=True, help="torch / OpenMP / MKL threads of this process")
    p.add_argument("--status", required=True, help="JSON file the parent polls")
    p.add_argument("--task", required=True, help="task name (experiment-<task>/train.py)")
    p.add_argument("--every", type=float, default=0.5, help="seconds between status updates while training")
    p.add_argument("train_argv", nargs=argparse.REMAINDER, help="flags for train.py, after --")
    args = p.parse_args(argv)
    if args.threads < 1:
        raise SystemExit(f"--threads must be at least 1, got {args.threads}")
    os.environ["OMP_NUM_THREADS"] = os.environ["MKL_NUM_THREADS"] = str(args.threads)
    import torch  # noqa: E402  (after the thread variables are set)
    torch.set_num_threads(args.threads)
    import hnn
    from hnn.runs import write_json

    train_argv = args.train_argv[1:] if args.train_argv[:1] == ["--"] else args.train_argv
    last = [0.0]

    def report(step: int, total: int) -> None:
        now = time.perf_counter()
        if now - last[0] >= args.every or step == total:
            last[0] = now
            write_json(args.status, {"step": step, "total": total})

    try:
        with hnn.training.report_progress(report):
            run = hnn.load_task(args.task, "train").main(train_argv)
    except Exception as err:
        write_json(args.status, {"error": str(err), "type": type(err).__name__})
        raise
    write_json(args.status, {"done": True, "run": str(run)})


if __name__ == "__main__":
    sys.exit(main())
