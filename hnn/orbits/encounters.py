"""The orbit tasks' close-encounter thresholds, without torch: the gravity code (``hnn.orbits.nbody``) redraws
by them and the orbit tasks' config (``hnn.orbits.config``) offers them as ``--min_separation``."""

# A trajectory is redrawn when two bodies come closer than this at any state the integrator
# evaluated. For these unit-mass systems the typical separation is 1-2 and the forces 0.3-1.
# Below r = 0.1 a pair's force 1/r^2 exceeds 100 and its potential -1/r exceeds the whole
# system's |H| (about 1) tenfold; its local orbital time sqrt(r^3 / 2) < 0.03 is 10x shorter
# than the data's sampling interval. There RK45 must cut its step by orders of magnitude (for
# the whole batch: the step is shared) and, as r -> 0, loses accuracy and energy to the 1/r^2
# singularity (a head-on collision cannot be integrated at all). Measured for a two-body
# fly-by at rtol 1e-9, atol 1e-6 and t in [0, 20]: relative energy error 8e-5 with pericentre
# 0.1, 1.5e-4 at 0.01, 3e-4 at 0.001, and 1.4k / 3k / 4.5k evaluations. Such rows (|dx/dt| of
# 100 and more) would also dominate the squared-error training loss. The 2-body orbits never
# come near the threshold (their closest approach is about 1.0); about 3% of the 3-body
# orbits do within t in [0, 5], and are redrawn. The tasks' default is 0 (keep every orbit, as
# the original did, so their tables are the paper's setting); 0.1 is the cleaned dataset that
# reproduce.py adds as an extra, labelled row.
MIN_SEPARATION = 0.1
TASK_MIN_SEPARATION = 0.0
