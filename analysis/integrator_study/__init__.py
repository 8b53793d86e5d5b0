"""The integrator study: speed at equal accuracy of every registered solver on every task
(``speed_accuracy``, the command; ``speed_measure`` and ``speed_report``, what it measures and writes)
and the long-horizon energy drift of the learned H (``energy_drift``)."""
