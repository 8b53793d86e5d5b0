"""Pendulum chains on the field's published protocols: ``peers`` (the peers' numbers beside ours)."""
