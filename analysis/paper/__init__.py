"""The paper's reproduction: ``reproduce`` (tables, figures, docs pages), ``registry`` (the figures a
task names in its ``task.py``), the figure modules, and ``regression_spread``."""
