"""rclpy nodes of ssa_fusion, one per module, each with `main()` for `ros2 run`.

A graph runs several single-threaded nodes side by side: a multi-threaded BLAS in each
would spin-wait against the others (a 10 ms Hankel-DMD fit took seconds that way), so
nodes default to one BLAS thread. Set OPENBLAS_NUM_THREADS to override.
"""

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")
