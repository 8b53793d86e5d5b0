"""The analysis of this repository, importable as ``hnn_analysis`` (pyproject maps the name to ``analysis/``).

Rooms by purpose, each importing only the others' public names:

- ``paper``: the paper's reproduction (``reproduce``: tables, figures, docs pages; the figure registry).
- ``scenes``: the scene study (``scene_study``, ``scene_metrics``, ``scene_report``).
- ``benchmarks``: the step, rollout, pixel, grouped-training and Ray-cost benchmarks against the
  arithmetic floor (``benchmark``, ``floor``, ``benchmark_orbits``, ``benchmark_pixels``, ``ray_overhead``),
  and every command's ``--quick`` against its budget (``quick_budgets``).
- ``integrator_study``: speed at equal accuracy of every solver (``speed_accuracy``), the energy drift.
- ``chains``: the peers' tables on pendulum chains and DGNet's protocol (``peers``, ``dgnet``).
- ``provenance`` (commit, versions, machine for every JSON written) and ``readme`` (the generated
  blocks of README.md and docs/). Training many runs is the library's ``hnn.sweep``.

``reproduce.py`` and ``scene_study.py`` at this level are the README's entry points
(``python analysis/reproduce.py --quick``); every command also runs by its own path. The name
``hnn_analysis`` comes from the install (``pip install -e .``): the commands import it like any package.
"""
