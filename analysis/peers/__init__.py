"""The peers' published numbers on pendulum chains beside ours (``peers``): CHNN's and LNN's protocols."""
