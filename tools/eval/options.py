"""Values the command line of `aeb eval` offers and the evaluation uses, in a module
that imports nothing of the eval extra (so that `aeb eval --help` lists every option
without it)."""

DEPTH_MODES = ("none", "lidar", "d435")
# Data sets: frames per task of the process pool or Dask cluster.
FRAMES_PER_TASK = 8
# The paper's Table IV thresholds: edge densities, for the verifiers that score one.
PAPER_SWEEP = (0.010, 0.025, 0.050, 0.080, 0.100, 0.150)
