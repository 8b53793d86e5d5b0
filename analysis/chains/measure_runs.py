"""``python analysis/chains/measure_runs.py RUN ...``: CHNN's rollout error of saved chain runs beside the published numbers.

For runs trained outside ``analysis/peers.py`` (other step budgets): each run folder's model is
rolled out on CHNN's test starts of its chain (``peer_measure.measure_chnn``) and its mean (median)
geometric-mean relative error printed beside the published CHNN and CLNN; writes ``measured.json``
under ``--out``.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import hnn
from hnn.io import write_json
from hnn_analysis.chains.peer_measure import measure_chnn


def main(argv=None) -> dict:
    p = hnn.cli.Parser(prog="measure_runs.py", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("runs", nargs="+", type=Path, help="run folders of experiment-chain/train.py (CHNN protocol)")
    p.add_argument("--starts", type=hnn.settings.int_at_least(1), default=100, help="test starts (CHNN's: 100)")
    p.add_argument("--out", type=Path, default=Path("."), help="folder of measured.json")
    args = p.parse_args(sys.argv[1:] if argv is None else argv)
    data, protocols = hnn.load_task("chain"), hnn.load_task("chain", "protocols")
    rows = []
    for folder in args.runs:
        model, saved, metrics = hnn.load_run(folder)
        if saved.get("protocol", "chnn") != "chnn":
            raise ValueError(f"{folder} trained on the {saved['protocol']!r} protocol; this measures CHNN's")
        chain = data.chnn_chain(saved["bobs"], saved.get("unit", False))
        found = measure_chnn(chain, {saved["model"]: model}, args.starts)
        peer = protocols.CHNN_PUBLISHED.get(saved["bobs"], {})
        rows.append({"run": str(folder), "bobs": saved["bobs"], "model": saved["model"], "steps": saved["total_steps"],
                     "train_seconds": metrics.get("train_seconds"), "ours": found[saved["model"]],
                     "floor": found["floor"], "published": {k: peer.get(k) for k in ("CHNN", "CLNN", "HNN")}})
        print(json.dumps(rows[-1]), flush=True)
    print("\n| N | kind | steps | train s (wall) | ours mean (median) | published CHNN | published CLNN | floor |")
    print("| --- " * 8 + "|")
    for row in rows:
        ours, pub = row["ours"], row["published"]
        cell = (f"blew up: {ours['blew_up']}" if "blew_up" in ours else f"{ours['mean']:.2e} ({ours['median']:.2e})")
        print(f"| {row['bobs']} | {row['model']} | {row['steps']} | {row['train_seconds']:.0f} | {cell} | "
              + " | ".join(f"{pub[k][0]:.2e} ({pub[k][1]:.2e})" if pub[k] else "" for k in ("CHNN", "CLNN"))
              + f" | {row['floor']['mean']:.2e} |")
    write_json(args.out / "measured.json", rows)
    return {"rows": rows}


if __name__ == "__main__":
    main()
