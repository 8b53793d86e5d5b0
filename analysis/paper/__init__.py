"""The paper's reproduction: ``reproduce`` (the command: tables, figures, docs pages), ``study`` (its rows
of runs, loaded and evaluated: the library the scene and measured studies train and read through too),
``registry`` (the figures a task names in its ``task.py``), the figure modules, and ``regression_spread``."""
