"""The analysis of this repository, importable as ``hnn_analysis`` (pyproject maps the name to ``analysis/``).

Rooms by purpose, each importing only the others' public names:

- ``paper``: the paper's reproduction (``reproduce``: tables, figures, docs pages; the figure registry).
- ``scenes``: the scene study (``scene_study``, ``scene_metrics``, ``scene_report``).
- ``speed``: benchmarks and the integrator study (``benchmark``, ``floor``, ``benchmark_orbits``,
  ``benchmark_pixels``, ``speed_accuracy``).
- ``sweep`` (mapping run configs to trained runs, here, in worker processes or on Ray),
  ``provenance`` (commit, versions, machine for every JSON written) and ``readme`` (the generated
  blocks of README.md and docs/).

``reproduce.py`` and ``scene_study.py`` at this level are the README's entry points
(``python analysis/reproduce.py --quick``); every command also runs by its own path.
"""
