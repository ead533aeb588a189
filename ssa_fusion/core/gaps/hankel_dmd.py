"""Hankel dynamic mode decomposition (time-delay DMD) for forecasting measurements.

The surrogate model of the paper (section 2.1): measurements ``z(k)`` (any channels,
e.g. GCRF position in km or range km / azimuth rad / elevation rad) sampled at a fixed
cadence are stacked into a Hankel (time-delay) matrix and a best-fit linear operator
``A`` with ``H[:, 1:] ~= A H[:, :-1]`` is identified in a rank-``r`` subspace. Forecasts
iterate that operator from the *last* Hankel column, so they continue right after the
last training sample.

Numerical choices (all float64):

* The Hankel matrix ``X = H[:, :-1]`` (``channels*delays`` x ``samples-delays``) is
  reduced by a thin SVD built on its smaller side (LQ factorisation, then the SVD of the
  small triangular factor; `_leading_subspace`): every singular value to ``eps *
  sigma_max``, so the kept subspace does not depend on the BLAS kernel's rounding.
* Rank selection (``rank=None``): the optimal hard threshold of Gavish & Donoho (2014)
  for unknown noise level, ``sigma > omega(beta) * median(sigma)`` over the
  ``min(rows, cols)`` singular values -- the same rule as PyDMD's ``svd_rank=0`` --
  capped at ``max_rank``. Whatever the rule (or a fixed ``rank``) asks for, no direction
  at or below the SVD's resolution ``max(rows, cols) * eps * sigma_max`` is kept
  (`resolvable_rank`): on noise-free data the median singular value sits at round-off,
  the threshold selects "everything", and this floor or the cap decides. Forecasts of
  the same data then agree across BLAS kernels to ~1e-7 of the data's scale (tested in
  ``test/core/test_blas_kernels.py``, tolerance 1e-6).
* The reduced operator is obtained by least squares in the reduced coordinates
  ``P = U^T H`` (QR of ``P_X^T``), i.e. ``Atilde = P_Y P_X^+``, together with the
  exact-DMD read-out ``C = Y_last P_X^+`` that maps reduced coordinates to the next
  sample. This never divides by (possibly tiny, inaccurate) singular values, so the
  forecast is ``z(N-1+k) = C Atilde^(k-1) U^T h_last`` (exact DMD operator
  ``Y X^+`` restricted to the rank-``r`` subspace, applied ``k`` times).
* Stabilisation (no exploding modes): ``Atilde`` is brought to real Schur form
  ``Q T Q^T`` and 1x1 / 2x2 diagonal blocks whose eigenvalue modulus exceeds a limit
  are rescaled onto that circle (phase kept, rest of the Schur form untouched, so
  nearly defective blocks such as a linear trend survive -- unlike an
  eigenvector-based projection). For horizons up to the fitted span (``samples -
  delays + 1`` steps) the limit is ``2^(1/span)`` -- growth the data can support,
  at most a factor 2 over the span; the slight apparent growth of the dominant
  modes of a J2 orbit (``|lambda| - 1 ~ 1e-4``) matters at the km level over 200
  steps. Beyond the span the limit is 1, so the forecast stays bounded forever.
* Angle channels are unwrapped (``np.unwrap``) before fitting and forecasts of them
  are wrapped back to ``[0, 2 pi)``.

Forecast covariance (paper section 4, ``Var(e) = R + A E[z z^T] A^T`` grows with
horizon): estimated from in-sample multi-step residuals. The fitted model is run ``h``
steps ahead from every training Hankel column at once (powers of the reduced operator,
vectorised) and the second moment of the error against the *measured* sample ``h``
steps later is taken per horizon, for horizons up to half the number of Hankel
columns. Beyond that the covariance is extended with a power law ``(h / h_max)^p``,
``p`` in ``[0, 2]`` fitted to the trace over the last octave of available horizons
(``p = 2``: linear error growth from a frequency error). The result is floored by
the one-step residual covariance ``residual_cov_`` (``C_h >= R`` in the PSD sense) and
its trace is made non-decreasing. Because errors are measured against noisy samples,
the covariance describes ``forecast - future measurement`` (it includes the sensor
noise ``R``, as in the paper), which is what a measurement that replaces a missing
one must carry.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from numpy.typing import ArrayLike, NDArray

from ssa_fusion.core.earth.frames import wrap_2pi

# scipy.linalg (14 MB resident) is imported by the functions that use it, so that a process
# that imports this module but fits no DMD (a catalog filter shard) does not hold it.

__all__ = ["HankelDMD", "resolvable_rank", "svht_rank"]

_COV_BUDGET = 400_000  # max (horizon, column) pairs in the covariance estimator
FloatArray = NDArray[np.float64]
GRAM_FLOOR = 1e-5  # of sigma_max: the smallest singular value `_gram_subspace` relies on
Residual = Callable[[FloatArray, NDArray[np.intp]], FloatArray]


def svht_rank(sigma: ArrayLike, rows: int, cols: int) -> int:
    """Optimal hard-threshold rank of Gavish & Donoho (2014), noise level unknown.

    Parameters
    ----------
    sigma : array_like, shape (k,)
        Singular values of the data matrix (any order, any unit).
    rows, cols : int
        Shape of the data matrix.

    Returns
    -------
    int
        Number of singular values above ``omega(beta) * median(sigma)`` with
        ``beta = min/max`` aspect ratio and the polynomial approximation
        ``omega = 0.56 beta^3 - 0.95 beta^2 + 1.82 beta + 1.43`` (at least 1).
    """
    s = np.asarray(sigma, dtype=float)
    beta = min(rows, cols) / max(rows, cols)
    omega = 0.56 * beta**3 - 0.95 * beta**2 + 1.82 * beta + 1.43
    return max(1, int(np.count_nonzero(s > omega * np.median(s))))


def psd_part(c: FloatArray) -> FloatArray:
    """Return the positive semi-definite part of symmetric matrices.

    Parameters
    ----------
    c : ndarray, shape (k, n, n)
        Symmetric matrices (any unit).

    Returns
    -------
    ndarray, shape (k, n, n)
        ``c`` with its negative eigenvalues set to zero (same unit).
    """
    w, v = np.linalg.eigh(c)
    out: FloatArray = (v * np.clip(w, 0.0, None)[:, None, :]) @ v.transpose(0, 2, 1)
    return out


def warm_up() -> None:
    """Import what a fit uses (scipy.linalg, ~0.3 s), so that the first fit does not.

    The fits import it on first use so that importing this module stays cheap; a process
    that will fit (the surrogate node) calls this at start, before measurements arrive, so
    its first forecast is not late by the import.
    """
    import scipy.linalg  # noqa: F401


def _hankel(z: FloatArray, delays: int) -> FloatArray:
    """Time-delay matrix, PyDMD ordering: column j = [z_j; z_{j+1}; ...; z_{j+d-1}].

    ``z`` is (channels, samples); result is (channels*delays, samples-delays+1), C order.
    """
    m, n = z.shape
    win = sliding_window_view(z, delays, axis=1)  # (m, n-d+1, d)
    return np.ascontiguousarray(win.transpose(2, 0, 1).reshape(m * delays, n - delays + 1))


def resolvable_rank(sigma: ArrayLike, rows: int, cols: int) -> int:
    """Count the singular values an SVD of a ``rows`` x ``cols`` matrix resolves.

    A backward-stable SVD returns every singular value to an absolute accuracy of about
    ``eps * sigma_max``, so values at or below ``max(rows, cols) * eps * sigma_max`` are
    round-off, and their singular vectors are whatever the BLAS kernel's rounding made of
    them (LAPACK's and ``numpy.linalg.matrix_rank``'s tolerance).

    Parameters
    ----------
    sigma : array_like, shape (k,)
        Singular values, descending (any unit).
    rows, cols : int
        Shape of the decomposed matrix.

    Returns
    -------
    int
        Count of ``sigma > max(rows, cols) * eps * sigma[0]`` (at least 1).
    """
    s = np.asarray(sigma, dtype=float)
    tol = max(rows, cols) * np.finfo(np.float64).eps * s[0]
    return max(1, int(np.count_nonzero(s > tol)))


def _leading_subspace(x: FloatArray, choose_rank: Callable[[FloatArray], int]
                      ) -> tuple[FloatArray, FloatArray]:
    """Singular values of ``x`` and its leading left singular vectors, to full precision.

    A thin SVD built on the smaller side: for a wide ``x`` (the usual Hankel matrix,
    fewer rows than columns) the LQ factorisation ``x = L Q^T`` (QR of ``x^T``) first,
    then the SVD of the small square ``L`` (``x`` and ``L`` share singular values and
    left singular vectors); for a tall ``x`` the thin SVD of ``x`` itself. Either way
    there are ``min(rows, cols)`` singular values, each accurate to ``eps * sigma_max``
    (a Gram-matrix eigen-decomposition resolves only ``sqrt(eps) * sigma_max``, so the
    directions it keeps below that depend on the BLAS kernel's rounding). Where the rank
    rule looks only at singular values far above that (noisy data), `_gram_subspace`
    gives the same result at a third of the cost, and is used.

    The kept rank is ``choose_rank(sigma)``, never above `resolvable_rank`: a direction
    the decomposition cannot resolve is never kept.

    Returns
    -------
    sigma : ndarray, shape (min(rows, cols),)
        All singular values of ``x``, descending.
    u : ndarray, shape (rows, r)
        Orthonormal left singular vectors of the ``r`` kept singular values, in order.
    """
    import scipy.linalg as sla
    rows, cols = x.shape
    if rows <= cols:
        fast = _gram_subspace(x, choose_rank)
        if fast is not None:
            return fast
        lower = sla.qr(x.T, mode="r", check_finite=False)[0][:rows].T
        u, sigma, _ = sla.svd(lower, check_finite=False)
    else:
        u, sigma, _ = sla.svd(x, full_matrices=False, check_finite=False)
    r = min(choose_rank(sigma), resolvable_rank(sigma, rows, cols))
    return sigma, np.ascontiguousarray(u[:, :r])


def _gram_subspace(x: FloatArray, choose_rank: Callable[[FloatArray], int]
                   ) -> tuple[FloatArray, FloatArray] | None:
    """`_leading_subspace` of a wide ``x`` through its Gram matrix, where that is precise.

    The eigenvalues of ``gram = x x^T`` are accurate to ``eps * sigma_max^2``, so singular
    values down to ``GRAM_FLOOR * sigma_max`` (1e-5) come out to ~1e-6 relative, and the
    leading eigenvectors span the leading singular subspace to ~1e-11 wherever the kept
    and the dropped singular values both lie above that floor. Then the rank rule sees
    the same values as with an SVD (the threshold's median too must lie above the floor),
    and the fit costs a third: the steps of LAPACK's ``dsyevr`` (tridiagonal reduction,
    eigenvalues, MRRR eigenvectors for the ``r`` kept only, back-transformation).

    Returns
    -------
    (sigma, u) as `_leading_subspace`, or None where the rank rule would look below the
    floor (noise-free data, whose median singular value is round-off): then only the SVD
    resolves what is kept.
    """
    import scipy.linalg as sla
    gram = x @ x.T
    n = gram.shape[0]
    if n < 3:
        return None
    lapack = sla.lapack
    lwork = int(lapack.dsytrd_lwork(n, lower=1)[0])
    c, diag, off, tau, info = lapack.dsytrd(gram, lower=1, lwork=lwork)
    if info != 0:
        return None
    ev = sla.eigh_tridiagonal(diag, off, eigvals_only=True, lapack_driver="stemr",
                              check_finite=False)
    sigma = np.sqrt(np.clip(ev[::-1], 0.0, None))
    r = choose_rank(sigma)
    floor = GRAM_FLOOR * sigma[0]
    if not (sigma[min(r, n - 1)] > floor and np.median(sigma) > floor):
        return None
    # dstemr overwrites its off-diagonal argument (a fresh array here); range 2 = by index
    found, _, z, info = lapack.dstemr(diag, np.append(off, 0.0), 2, 0.0, 0.0, n - r + 1, n)
    if info == 0 and found == r:
        z = z[:, :r]
    else:  # MRRR can fail on clustered eigenvalues; dsyevr then uses bisection + inverse it.
        z = sla.eigh_tridiagonal(diag, off, select="i", select_range=(n - r, n - 1),
                                 lapack_driver="stebz", check_finite=False)[1]
    # Q of dsytrd(lower) = diag(1, Q'), Q' the QR-format reflectors stored below row 0
    qz, _, info = lapack.dormqr("L", "N", c[1:, : n - 1], tau, z[1:], max(1, 64 * r))
    if info != 0:
        return None
    z[1:] = qz
    return sigma, np.ascontiguousarray(z[:, ::-1])


def _clip_schur(t: FloatArray, rho: float) -> tuple[FloatArray, NDArray[np.complex128]]:
    """Rescale real-Schur diagonal blocks with ``|lambda| > rho`` onto ``|lambda| = rho``.

    Parameters
    ----------
    t : ndarray, shape (r, r)
        Real quasi-upper-triangular Schur factor (not modified).
    rho : float
        Largest eigenvalue modulus allowed (dimensionless, per step).

    Returns
    -------
    t : ndarray, shape (r, r)
        Copy with clipped diagonal blocks (phases kept, off-diagonal part untouched).
    eigs : ndarray, shape (r,), complex
        Its eigenvalues (block order; conjugate pairs adjacent, positive imaginary first).
    """
    t = t.copy()
    r = t.shape[0]
    sub = np.zeros(r, dtype=bool)
    if r > 1:
        sub[:-1] = np.diag(t, -1) != 0.0  # True at the first index of a 2x2 block
    eigs = np.empty(r, dtype=complex)
    i = 0
    while i < r:
        if sub[i]:
            blk = t[i : i + 2, i : i + 2]
            det = blk[0, 0] * blk[1, 1] - blk[0, 1] * blk[1, 0]  # |lambda|^2 of the pair
            if det > rho * rho:
                blk *= rho / np.sqrt(det)
                det = rho * rho
            half_tr = 0.5 * (blk[0, 0] + blk[1, 1])
            im = np.sqrt(max(det - half_tr * half_tr, 0.0))
            eigs[i] = complex(half_tr, im)
            eigs[i + 1] = complex(half_tr, -im)
            i += 2
        else:
            if abs(t[i, i]) > rho:
                t[i, i] = np.copysign(rho, t[i, i])
            eigs[i] = t[i, i]
            i += 1
    return t, eigs


def _orbit(t: FloatArray, x0: FloatArray, n: int) -> FloatArray:
    """Columns ``x0, t x0, ..., t^(n-1) x0`` (shape (r, n)) by repeated doubling."""
    seq = x0[:, None]
    p = t
    while seq.shape[1] < n:
        seq = np.concatenate((seq, p @ seq), axis=1)
        if seq.shape[1] < n:
            p = p @ p
    return seq[:, :n]


def _stacked_powers(c: FloatArray, t: FloatArray, n: int) -> FloatArray:
    """``[c, c t, c t^2, ..., c t^(n-1)]`` stacked on axis 0 by repeated doubling.

    ``c`` is (m, r) and ``t`` (r, r); result is (n, m, r). ``log2(n)`` matmuls.
    """
    out = c[None, :, :]
    p = t
    while out.shape[0] < n:
        out = np.concatenate((out, out @ p), axis=0)
        if out.shape[0] < n:
            p = p @ p
    return out[:n]


class HankelDMD:
    """Hankel-DMD surrogate: fit on a window of measurements, forecast ahead.

    Parameters
    ----------
    delays : int
        Number of time delays ``d`` (rows of the Hankel matrix = channels * d).
    rank : int or None
        Truncation rank; ``None`` selects it automatically (Gavish-Donoho optimal
        hard threshold, capped at ``max_rank``).
    angle_channels : sequence of int
        Channels holding angles in rad (e.g. ``(1,)`` for azimuth of range/az/el);
        unwrapped before fitting, forecasts wrapped to ``[0, 2 pi)``.
    max_rank : int
        Upper bound of the automatic rank (cost and noise-free-data guard).

    Attributes
    ----------
    rank_ : int
        Rank used.
    eigs : ndarray, shape (rank_,), complex
        Discrete-time eigenvalues of the fitted reduced operator (as PyDMD's ``eigs``;
        may exceed 1 in modulus slightly).
    eigs_stable_ : ndarray, shape (rank_,), complex
        Eigenvalues used beyond the fitted span, ``|eigs_stable_| <= 1``.
    modes : ndarray, shape (channels*delays, rank_), complex
        Exact DMD modes (eigenvectors of the operator in Hankel space, PyDMD layout).
    residual_cov_ : ndarray, shape (channels, channels)
        One-step-ahead in-sample residual covariance, measurement units squared.
    """

    def __init__(
        self,
        delays: int,
        rank: int | None = None,
        angle_channels: Sequence[int] = (),
        *,
        max_rank: int = 48,
    ) -> None:
        if delays < 1:
            raise ValueError("delays must be >= 1")
        if rank is not None and rank < 1:
            raise ValueError("rank must be >= 1 or None")
        if max_rank < 1:
            raise ValueError("max_rank must be >= 1")
        self.delays = int(delays)
        self.rank = rank
        self.angle_channels = tuple(int(c) for c in angle_channels)
        self.max_rank = int(max_rank)
        self._fitted = False

    # ------------------------------------------------------------------ fit
    def fit(self, z: ArrayLike) -> HankelDMD:
        """Identify the model from measurements at a fixed cadence.

        Parameters
        ----------
        z : array_like, shape (channels, samples)
            Measurements, oldest first, in their own units (km, rad, ...). Needs
            ``samples >= delays + 2``.

        Returns
        -------
        HankelDMD
            ``self``.
        """
        import scipy.linalg as sla
        z = np.array(z, dtype=np.float64, ndmin=2)
        if z.ndim != 2:
            raise ValueError("z must be (channels, samples)")
        m, n = z.shape
        d = self.delays
        if n < d + 2:
            raise ValueError(f"need at least delays + 2 = {d + 2} samples, got {n}")
        if not np.all(np.isfinite(z)):
            raise ValueError("z contains NaN or inf")
        if self.angle_channels:
            idx = list(self.angle_channels)
            z[idx] = np.unwrap(z[idx], axis=1)

        h = _hankel(z, d)  # (m d, ncol)
        x = h[:, :-1]
        rmax: int = min(x.shape)

        def choose_rank(sigma: FloatArray) -> int:
            if self.rank is None:
                return min(svht_rank(sigma, *x.shape), self.max_rank, rmax)
            return min(int(self.rank), rmax)

        sigma, u = _leading_subspace(x, choose_rank)
        r = u.shape[1]
        p = u.T @ h  # reduced coordinates of every Hankel column, (r, ncol)

        # Least squares [Atilde; C] = [P_Y; Y_last] P_X^+ via QR of P_X^T.
        q, rr = np.linalg.qr(p[:, :-1].T)
        rhs = np.concatenate((p[:, 1:], h[-m:, 1:]), axis=0)  # (r + m, ncol-1)
        coef = sla.solve_triangular(rr, (rhs @ q).T, check_finite=False).T
        a_tilde = coef[:r]
        c_out = coef[r:]

        t_raw, qs = sla.schur(a_tilde, output="real", check_finite=False)
        ncol = h.shape[1]
        # Transient growth is allowed up to a factor 2 over the fitted span (ncol steps);
        # beyond that span the operator is fully stabilised (|lambda| <= 1).
        self._k_switch = ncol
        _, eigs = _clip_schur(t_raw, np.inf)
        rho = np.abs(eigs).max()
        t = _clip_schur(t_raw, 2.0 ** (1.0 / ncol))[0] if rho > 2.0 ** (1.0 / ncol) else t_raw
        t_stab, eigs_stable = _clip_schur(t_raw, 1.0) if rho > 1.0 else (t_raw, eigs)

        self._u = u
        self._t_raw = t_raw
        self._t = t  # operator for horizons <= ncol, Schur coordinates
        self._t_stab = t_stab  # operator beyond ncol
        self._qs = qs
        self._c = c_out @ qs  # read-out in Schur coordinates, (m, r)
        self._b = qs.T @ p  # Schur coordinates of every Hankel column, (r, ncol)
        self._z = z
        self._h = h
        self.eigs = eigs
        self.eigs_stable_ = eigs_stable
        self.rank_ = r
        self.singular_values_ = sigma
        self.n_channels_ = m
        self.n_samples_ = n
        # One-step residual: prediction of z_{j+d} from column j, j = 0..ncol-2.
        res = self._c @ self._b[:, :-1] - z[:, d:]
        self.residual_cov_ = (res @ res.T) / res.shape[1]
        self._cov_cache: FloatArray | None = None
        self._modes: NDArray[np.complex128] | None = None
        self._fitted = True
        return self

    def _check(self) -> None:
        if not self._fitted:
            raise RuntimeError("call fit() first")

    @property
    def operator(self) -> FloatArray:
        """Fitted reduced operator ``Atilde`` (rank_ x rank_) in the POD basis (unclipped)."""
        self._check()
        op: FloatArray = self._qs @ self._t_raw @ self._qs.T
        return op

    @property
    def modes(self) -> NDArray[np.complex128]:
        """Exact DMD modes ``Y P_X^+ W`` (channels*delays, rank_), PyDMD layout."""
        import scipy.linalg as sla
        self._check()
        if self._modes is None:
            from scipy.optimize import linear_sum_assignment  # 0.2 s to import; modes only

            y = self._h[:, 1:]
            q, rr = np.linalg.qr(self._b[:, :-1].T)
            read_all = sla.solve_triangular(rr, (y @ q).T, check_finite=False).T
            w_eigs, w = np.linalg.eig(self._t_raw)
            # match eig()'s order to self.eigs (same spectrum, possibly permuted)
            _, col = linear_sum_assignment(np.abs(self.eigs[:, None] - w_eigs[None, :]))
            self._modes = read_all @ w[:, col]
        return self._modes

    # ------------------------------------------------------------- forecast
    def forecast(self, n_steps: int) -> FloatArray:
        """Forecast the ``n_steps`` samples that follow the last training sample.

        Parameters
        ----------
        n_steps : int
            Number of future samples (same cadence as the training data).

        Returns
        -------
        ndarray, shape (channels, n_steps)
            Forecast measurements in the training units; angle channels in ``[0, 2 pi)``.
        """
        self._check()
        if n_steps < 1:
            return np.zeros((self.n_channels_, 0))
        k1 = min(n_steps, self._k_switch)
        seq = _orbit(self._t, self._b[:, -1], k1)
        if n_steps > k1:
            x_k = self._t @ seq[:, -1]
            seq = np.concatenate((seq, _orbit(self._t_stab, x_k, n_steps - k1)), axis=1)
        out: FloatArray = self._c @ seq
        if self.angle_channels:
            idx = list(self.angle_channels)
            out[idx] = wrap_2pi(out[idx])
        return out

    def _empirical_cov(self, k_need: int, residual: Residual | None = None) -> FloatArray:
        """In-sample error second moments per horizon 1..k, shape (k, m', m').

        ``k = min(k_need, k_max)`` with ``k_max = ncol // 2`` (at least half of the
        Hankel columns contribute at every horizon). The error is ``pred - z[:, target]``
        or ``residual(pred, target)``. Cached for the default error only.
        """
        ncol = self._b.shape[1]
        k_max = max(1, min(k_need, ncol // 2))
        if residual is None and self._cov_cache is not None and (
                self._cov_cache.shape[0] >= k_max):
            cached: FloatArray = self._cov_cache[:k_max]
            return cached
        # Column stride bounds the work array to ~_COV_BUDGET error vectors.
        stride = max(1, -(-k_max * ncol // _COV_BUDGET))
        j = np.arange(0, ncol, stride)
        b = self._b[:, j]
        d = self.delays
        read = _stacked_powers(self._c, self._t, k_max)  # (k, m, r)
        kk, m, r = read.shape
        pred = (read.reshape(kk * m, r) @ b).reshape(kk, m, j.size)
        k = np.arange(1, k_max + 1)
        tgt = (d - 1) + k[:, None] + j[None, :]  # sample index predicted
        valid = tgt < self.n_samples_
        tgt = np.where(valid, tgt, 0)
        if residual is None:
            err = pred - self._z[:, tgt].transpose(1, 0, 2)
        else:
            err = np.asarray(residual(pred, tgt), dtype=np.float64)
        err *= valid[:, None, :]
        cnt = valid.sum(axis=1).astype(float)
        cov: FloatArray = np.einsum("kaj,kbj->kab", err, err) / cnt[:, None, None]
        if residual is None:
            self._cov_cache = cov
        return cov

    def forecast_covariance(self, n_steps: int,
                            residual: Residual | None = None) -> FloatArray:
        """Covariance of the forecast errors for horizons 1..n_steps.

        Parameters
        ----------
        n_steps : int
            Number of forecast steps (as in :meth:`forecast`).
        residual : callable, optional
            ``residual(pred, target) -> err``: the error of in-sample predictions
            ``pred`` (k, channels, J) of the training samples with indices ``target``
            (k, J), shape (k, m', J), in another space than the training data's (e.g. the
            measurement a lifted observable came from). Default ``pred - z[:, target]``.

        Returns
        -------
        ndarray, shape (n_steps, m', m')
            Symmetric PSD covariances (measurement units squared, angles in rad^2)
            of ``forecast - future measurement``; ``>=`` the one-step covariance and
            with a non-decreasing trace. See the module docstring for the estimator.
        """
        self._check()
        if n_steps < 1:
            m = self.n_channels_
            return np.zeros((0, m, m))
        emp = self._empirical_cov(n_steps, residual)
        k_max = emp.shape[0]
        if n_steps <= k_max:
            cov = emp[:n_steps].copy()
        else:
            tr = np.trace(emp, axis1=1, axis2=2)
            half = max(1, k_max // 2)
            if k_max > 1 and tr[half - 1] > 0.0 and tr[-1] > 0.0:
                p = np.log(tr[-1] / tr[half - 1]) / np.log(k_max / half)
                p = float(np.clip(p, 0.0, 2.0))
            else:
                p = 2.0
            k_ext = np.arange(k_max + 1, n_steps + 1, dtype=float)
            ext = emp[-1][None] * ((k_ext / k_max) ** p)[:, None, None]
            cov = np.concatenate((emp, ext), axis=0)
        cov = 0.5 * (cov + cov.transpose(0, 2, 1))
        # Floor: C_h >= R (one-step residual covariance) in the PSD sense.
        r0 = self.residual_cov_ if residual is None else emp[0]
        cov = r0 + psd_part(cov - r0)
        # Non-decreasing trace: scale up any horizon that falls below the running max.
        tr = np.trace(cov, axis1=1, axis2=2)
        run = np.maximum.accumulate(tr)
        scale = np.where(tr > 0.0, run / np.where(tr > 0.0, tr, 1.0), 1.0)
        cov *= scale[:, None, None]
        out: FloatArray = 0.5 * (cov + cov.transpose(0, 2, 1))
        return out
