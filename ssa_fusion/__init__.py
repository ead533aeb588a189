"""ssa_fusion: live state estimation of partly observed satellites (Hankel-DMD surrogate + EKF)."""

import os
import sys

__version__ = "0.1.0"

_THREAD_VARS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


def limit_blas_threads() -> None:
    """Default BLAS/OpenMP to one thread; call it before numpy is first imported.

    ssa_fusion runs several single-threaded processes side by side; a multi-threaded BLAS
    in each spin-waits against the others (a 10 ms Hankel-DMD fit took seconds that way).
    An explicit OPENBLAS_NUM_THREADS etc. in the environment wins. Changes the process
    environment, so only the entry points call it (a node's or the CLI's main, conftest).

    OpenBLAS reads its thread count when it is loaded (numpy's when numpy is first
    imported; scipy's when scipy.linalg is). If numpy is imported already and none of the
    variables was set, the libraries loaded so far are also set to one thread at run time,
    with threadpoolctl where it is installed.
    """
    explicit = any(var in os.environ for var in _THREAD_VARS)
    for var in _THREAD_VARS:
        os.environ.setdefault(var, "1")
    if explicit or "numpy" not in sys.modules:
        return
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:
        return
    threadpool_limits(limits=1)
