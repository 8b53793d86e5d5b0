"""The stress study's machinery (``analysis/stress.py`` is its command): the grid of fits and rollouts
(``stress_grid``), its tables (``stress_report``) and the LNN's start on CHNN's chains (``lnn_start``)."""
