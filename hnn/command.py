"""A ``train.py``'s whole command: parse its flags (``hnn.cli``), reuse the complete run of the same
settings (``--force`` retrains it and replaces it) or train one (``hnn.runs``), and print one line
saying where the run is and what happened to it. ``run_main`` runs it: the package's input errors
raised while running (a missing data file, say) become one ``error:`` line, and Ctrl-C one line
saying what was kept. Torch loads only once the flags are known good: ``--help`` and flag errors
answer before it.

    def main(argv=None):
        return hnn.command.train(Config, argv)

    if __name__ == "__main__":
        hnn.command.run_main(main)
"""
from __future__ import annotations

import sys
from collections.abc import Callable, Sequence
from pathlib import Path

from .cli import USAGE_ERROR, one_line, parse_created
from .io import WriteError

INTERRUPTED = 130   # the shell's code for a command ended by Ctrl-C (128 + SIGINT)
# Exceptions that mean "the input is wrong", not "the code is": values the parser cannot check
# (the package raises ValueError naming the value and the fix), missing data files, a --save_dir
# that cannot be written, and a write that failed there (a full disk: hnn.io.WriteError). Anything
# else keeps its traceback.
INPUT_ERRORS = (ValueError, FileNotFoundError, NotADirectoryError, PermissionError, WriteError)


def train(cls, argv: Sequence[str] | None = None, before: Callable | None = None) -> Path:
    """A ``train.py``'s command: the run of config class ``cls`` that ``argv`` asks for; returns its folder.

    A complete run of the same settings (``RunConfig.identity``) in ``--save_dir`` is reused, not
    retrained; ``--force`` retrains it and replaces its folder. Prints one line: where the run
    is and what happened to it (trained, reused, replaced; a ``--save_dir`` created on the way).
    Torch loads after the flags and the config's own input checks pass; the run trains on
    ``config.threads`` torch threads (the caller's count is restored after). ``before(config)``, if given,
    runs after them (a task's notes on its input). A ``--save_dir`` created here and left empty by an
    error or Ctrl-C is removed again.
    """
    config, created = parse_created(cls, argv)
    try:
        config.check_inputs()
        if before is not None:
            before(config)
        from .runs import find_run, run_experiment      # the heavy imports, once the input is known good
        found = find_run(config)
        if found is not None and not config.force:
            print(f"reused the complete run at {found}: it was trained with these settings already, so nothing "
                  "trained (--force retrains it and replaces the folder)")
            return found
        from .threads import torch_threads
        with torch_threads(config.threads):     # the run's own count (docs/speed.md#threads), the caller's after
            folder = run_experiment(config)
    except BaseException:
        for new in created:         # deepest first; rmdir refuses a folder that holds anything
            try:
                new.rmdir()
            except OSError:
                break
        raise
    notes = [f"created {created[0]}, which did not exist"] if created else []
    if found is not None:
        notes.append("replaced the complete run of the same settings that was there (--force)")
    print(f"saved the run to {folder}" + (f" ({'; '.join(notes)})" if notes else ""))
    return folder


def run_main(main: Callable[[list[str]], Path], argv: Sequence[str] | None = None) -> Path:
    """Run a ``train.py``'s ``main(argv)`` as a command (``argv`` defaults to ``sys.argv[1:]``);
    returns what it returns (the run folder; ``main`` says where it went).

    An input error raised while running (one of ``INPUT_ERRORS``) becomes one ``error: <message>``
    line on stderr and exit code 2; Ctrl-C one line saying what was kept, and exit code 130. With
    ``--debug`` both propagate with their traceback.
    """
    argv = sys.argv[1:] if argv is None else list(argv)
    debug = "--debug" in argv
    try:
        return main(argv)
    except INPUT_ERRORS as err:
        if debug:
            raise
        print(f"error: {one_line(err) or type(err).__name__}", file=sys.stderr)
        sys.exit(USAGE_ERROR)
    except KeyboardInterrupt:
        if debug:
            raise
        print("interrupted: the run in progress was discarded (a run folder is written whole or not at all); "
              "every run saved before stays", file=sys.stderr)
        sys.exit(INTERRUPTED)
