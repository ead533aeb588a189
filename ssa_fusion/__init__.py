"""ssa_fusion: live state estimation of partly observed satellites (Hankel-DMD surrogate + EKF)."""

import os

__version__ = "0.1.0"


def limit_blas_threads() -> None:
    """Default BLAS/OpenMP to one thread (before numpy is imported).

    ssa_fusion runs several single-threaded processes side by side; a multi-threaded BLAS
    in each spin-waits against the others (a 10 ms Hankel-DMD fit took seconds that way).
    An explicit OPENBLAS_NUM_THREADS etc. in the environment wins.
    """
    for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(var, "1")
