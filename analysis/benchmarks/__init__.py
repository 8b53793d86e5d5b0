"""Benchmarks: the training step, rollouts, the pixel model, grouped training and the Ray cost, each
against the arithmetic floor or the original's code measured in the same process (``benchmark`` is the
main command; ``benchmark_jobs`` runs its jobs, ``benchmark_report`` writes its tables)."""
