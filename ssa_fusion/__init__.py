"""ssa_fusion: live state estimation of partly observed satellites (Hankel-DMD surrogate + EKF)."""

__version__ = "0.1.0"
