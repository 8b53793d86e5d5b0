"""Pendulum chains on the field's published protocols: ``peers`` (the command: the peers' numbers beside
ours), its settings and runs (``peer_plan``), its measurements (``peer_measure``) and its table
(``peer_table``); ``dgnet`` (DGNet's protocol: the command; ``dgnet_protocol``, its library) and
``measure_runs``."""
