"""The analysis of this repository, importable as ``hnn_analysis`` (pyproject maps the name to ``analysis/``).

Rooms by purpose, each importing only the others' public names:

- ``paper``: the paper's reproduction (``reproduce``: tables, figures, docs pages; the figure registry).
- ``scenes``: the scene study (``scene_study``, ``scene_metrics``, ``scene_report``).
- ``benchmarks``: the step, rollout, pixel, grouped-training and Ray-cost benchmarks against the
  arithmetic floor (``benchmark``, ``floor``, ``benchmark_orbits``, ``benchmark_pixels``, ``ray_overhead``),
  and every command's ``--quick`` against its budget (``quick_budgets``).
- ``integrator_study``: speed at equal accuracy of every solver (``speed_accuracy``), the energy drift.
- ``extremes``: the stress study's grid, tables and the LNN's start (``stress.py`` is its command).
- ``chains``: the peers' tables on pendulum chains and DGNet's protocol (``peers``, ``dgnet``).
- ``fits``: the least-squares fits measured: the Sampling-HNNs protocols and the fits beside Adam and
  SINDy on the paper's tasks and the chains (``sampling_hnns``, ``fit_tasks``).
- ``provenance`` (commit, versions, machine for every JSON written) and ``pages`` (the generated
  blocks of README.md and docs/, and the seeds behind their verdicts; ``readme`` is its command). Training many runs is the library's ``hnn.sweeps.sweep``.

``reproduce.py`` and ``scene_study.py`` at this level are the README's entry points
(``python analysis/reproduce.py --quick``); every command also runs by its own path. The name
``hnn_analysis`` comes from the install (``pip install -e .``): the commands import it like any package.

The rooms and which may import which (``_ROOMS``, ``_MAY_IMPORT``; ``tests/test_layers.py`` reads every
import of every module against them, inside functions too): a room imports its own modules, those of
the rooms its row names, and ``hnn``; ``hnn`` imports none of them.

- shared: what every command uses (``commands``, ``provenance``, ``pages``, ``plotting``,
  ``training_cost``, ``plan``: a study's estimate before it starts); it imports no room;
- ``paper``, ``integrator_study``, ``chains``, ``extremes``: each on the shared modules alone;
- ``benchmarks``: also the studies whose quick modes it times beside their plans (``paper``, ``scenes``, ``chains``);
- ``fits``: also the paper's rows of runs and figure registry (its tasks' runs and energy protocols);
- ``scenes``: also the paper's rows of runs and figure registry, and the integrator study's settings;
- entry: the commands at this level (the README's entry points, ``arm``, ``stress``, ``readme``, ``score``,
  ``units_check``, ``bodies``), on any room.
"""

# room -> its units: a folder, or a module at this level by its name ("__init__": this file)
_ROOMS = {
    "shared": ("__init__", "commands", "provenance", "pages", "plotting", "training_cost", "plan"),
    "paper": ("paper",),
    "extremes": ("extremes",),
    "benchmarks": ("benchmarks",),
    "integrator_study": ("integrator_study",),
    "chains": ("chains",),
    "fits": ("fits",),
    "scenes": ("scenes",),
    "entry": ("reproduce", "scene_study", "peers", "arm", "stress", "readme", "score", "units_check", "bodies"),
}
# room -> the rooms it may import besides its own
_MAY_IMPORT = {
    "shared": (),
    "paper": ("shared",),
    "benchmarks": ("shared", "paper", "scenes", "chains"),
    "integrator_study": ("shared",),
    "chains": ("shared",),
    "extremes": ("shared",),
    "fits": ("shared", "paper"),
    "scenes": ("shared", "paper", "integrator_study"),
    "entry": ("shared", "paper", "scenes", "chains", "extremes"),
}
