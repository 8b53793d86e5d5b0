"""Each least-squares fit beside its arithmetic floor: the linear algebra it performs, timed alone in the same process.

    python analysis/fits/fit_floor.py                   # the table; results/fit_floor/fit_floor.json
    python analysis/fits/fit_floor.py --update-docs     # and docs/speed.md's section fit-floor
    python analysis/fits/fit_floor.py --quick           # without the fits of minutes (the double pendulum, 10000)

What is timed and how the floor is made: ``hnn_analysis.fits.floor``.
"""
from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

import hnn
from hnn.io import write_json
from hnn_analysis import commands, pages
from hnn_analysis.fits.floor import FITS, SECTION, dataset, measure, section
from hnn_analysis.provenance import cpu_snapshot, others_load, provenance


def main(argv=None) -> dict:
    argv = sys.argv[1:] if argv is None else list(argv)
    p = hnn.cli.Parser(prog="fit_floor.py", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--repeats", type=hnn.settings.int_at_least(1), default=3, help="fits timed per row (default 3)")
    p.add_argument("--quick", action="store_true", help="skip the fits of minutes (the double pendulum at width "
                   "10000: about 5 minutes on 2 cores, 6 GiB; not with --update-docs)")
    p.add_argument("--only", nargs="+", type=hnn.settings.int_at_least(0), default=None, metavar="ROW",
                   help=f"these rows of the table only (0-{len(FITS) - 1}; not with --update-docs)")
    p.add_argument("--data-dir", type=Path, default=None,
                   help="where the tasks' datasets are cached (default: each task's folder, as train.py)")
    p.add_argument("--out", type=Path, default=None, help="folder of fit_floor.json (default results/fit_floor)")
    p.add_argument("--update-docs", dest="update_docs", action="store_true",
                   help=f"write docs/speed.md's section {SECTION}")
    args = p.parse_args(argv)
    if args.update_docs and (args.only or args.quick):
        p.error("--update-docs writes every row; drop --only and --quick")
    cases = [case for i, case in enumerate(FITS) if (args.only is None or i in args.only) and not (args.quick and case.slow)]
    if hnn.fits.sindy.version() is None:
        cases = [case for case in cases if case.fit != "sindy"]
    out = args.out or hnn.tasks.repo_root() / "results" / "fit_floor"
    meta = {**provenance(), "command": commands.portable_command(argv, "analysis/fits/fit_floor.py")}
    load_before, start, rows, rates, datasets = os.getloadavg()[0], cpu_snapshot(), [], {}, {}
    for case in cases:
        if case.data not in datasets:
            datasets[case.data] = dataset(case.data, args.data_dir)
        row = measure(case, datasets[case.data], args.repeats, rates)
        rows.append(row)
        print(f"{row['label']}: {row['seconds']:.3g} s, floor {row['floor']:.3g} s, ratio {row['ratio']:.2f}", flush=True)
    results = {"meta": meta, "repeats": args.repeats, "rows": rows, "load": [load_before, os.getloadavg()[0]],
               "others": others_load(start, cpu_snapshot()),
               "gemm_gflops": {t: r / 1e9 for t, r in rates.items()}}
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "fit_floor.json", results)
    text = section(results)
    print("\n" + text + f"\nwrote {out / 'fit_floor.json'}")
    if args.update_docs:
        print(f"updated {pages.update_section(SECTION, text)}")
    return results


if __name__ == "__main__":
    main()
