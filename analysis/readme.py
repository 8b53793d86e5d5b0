"""Generated pages: text pasted between ``<!-- NAME:begin -->`` and ``<!-- NAME:end -->`` of
README.md or a page of docs/, and the curated figures in docs/figures/.

Every generated section is written only this way, never by hand, by the command that measures it:

    python analysis/reproduce.py --update-docs        # docs/results.md, the README's headline, docs/figures/
    python analysis/benchmarks/benchmark.py --update-docs        # docs/speed.md
    python analysis/integrator_study/speed_accuracy.py --update-docs   # docs/integrators.md
    python analysis/scene_study.py --update-docs      # docs/scenes.md, the README's model guide
    python analysis/benchmarks/ray_overhead.py [--full] --update-docs   # docs/sweeps.md: Ray against local
    python analysis/benchmarks/threads.py --update-docs      # docs/speed.md: what a second thread buys
    python analysis/benchmarks/quick_budgets.py --update-docs   # docs/speed.md: every --quick against its budget
    python analysis/readme.py timing results/results.json   # docs/speed.md: a saved run's stage times
    python analysis/readme.py kinds                          # README.md and docs/python.md: the model kinds
    python analysis/stress.py --update-docs           # docs/stress.md: every kind at the extremes
    python analysis/readme.py check                          # which pages are older than the code

A page's stamp names the commit that made it; ``check`` (and ``reproduce.py`` before it writes)
warns about every section stamped before the last change to ``hnn/`` or ``experiment-*/`` (a
commit that says ``Numbers-unchanged: <why>`` in its message does not count), and
about a model-kind section that differs from what the rows of ``hnn.MODEL_KINDS`` make.
"""
import argparse
import json
from pathlib import Path

import hnn

from hnn_analysis.pages import DECLARED, declared_out_of_date, kinds_text, stale, timing_text, update_section


def main(argv=None) -> None:
    p = hnn.cli.Parser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("what", choices=["timing", "kinds", "check"],
                   help="timing: the full-run section from a results.json; kinds: the model kinds of README.md "
                        "and docs/python.md; check: list the stale pages (exit code 1 if any)")
    p.add_argument("results", type=Path, nargs="?", help="a results.json written by analysis/reproduce.py")
    args = p.parse_args(argv)
    if args.what == "kinds":
        for name in DECLARED:
            print(f"updated the {name} section of {update_section(name, kinds_text(name))}")
        return
    if args.what == "check":
        lines = stale() + declared_out_of_date()
        print("\n".join(lines) if lines else "every generated page is stamped at or after the last code change")
        raise SystemExit(1 if lines else 0)
    if args.results is None:
        p.error("timing needs the results.json of a full reproduce.py run, e.g. results/results.json")
    page = update_section("full-run", timing_text(json.loads(args.results.read_text())))
    print(f"updated the full-run section of {page} from {args.results}")


if __name__ == "__main__":
    main()
