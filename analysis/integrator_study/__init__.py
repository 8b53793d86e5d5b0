"""The integrator study: speed at equal accuracy of every registered solver on every task
(``speed_accuracy``) and the long-horizon energy drift of the learned H (``energy_drift``)."""
