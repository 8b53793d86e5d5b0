"""Speed: ``benchmark`` (against the original's way of working; ``floor``, a step's matrix products
alone), ``benchmark_orbits``, ``benchmark_pixels`` and ``speed_accuracy`` (the integrator study)."""
