"""The analysis of this repository, importable as ``hnn_analysis`` (pyproject maps the name to ``analysis/``).

Commands (run by path from a checkout, as the README does, or with ``python -m hnn_analysis.<name>``
once installed): ``reproduce`` (the paper's tables and figures), ``benchmark``,
``benchmark_orbits``, ``benchmark_pixels``, ``speed_accuracy``, ``regression_spread``, ``readme``
(the generated pages) and ``train_worker`` (one run of ``reproduce --jobs N``). Modules:
``figures``, ``mischief``, ``orbit_figures``, ``pixel_figures`` (plotting), ``registry`` (the
figures a task names in its ``task.py``, by name), ``sweep`` (training a list of runs here, in
worker processes or on Ray, for ``reproduce`` and the other sweeps) and ``floor`` (a training
step's matrix products, timed alone, for ``benchmark``).
"""
