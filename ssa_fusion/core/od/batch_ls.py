"""Batch least squares over a window of measurements: differential correction of an orbit.

`fit` estimates the state at one epoch (the window's last measurement by default) and,
where they pay, force-model parameters (`force_model.PARAMETERS`: a drag factor on the
``drag`` model, constant empirical accelerations in RTN) from every measurement of the
window at once, by Gauss-Newton iterations (`gauss_newton`, the generic solver):

* each iteration integrates the reference trajectory from the epoch to every measurement
  epoch with its state transition matrix and parameter sensitivities in one compiled call
  per side of the epoch (`force_model.trajectory`, the augmented variational equations: no
  finite differences), predicts each measurement with its station's model (`measurement`,
  light time as configured) and its analytic Jacobian, and whitens residual and partials by
  the measurement's own covariance R (``L^-1`` of its Cholesky factor); angle residuals are
  wrapped to (-pi, pi];
* the correction solves the whitened normal equations by a column-scaled SVD (the state's
  km and km/s and the parameters' units differ by orders of magnitude), with the a-priori
  information of the solve-for parameters (`BatchOptions.param_sigma`) and, optionally, of
  the state;
* outlier editing, as Orekit's ``OutlierFilter`` and GMAT's batch estimator do: a measurement
  whose whitened residual exceeds ``k`` in any channel is left out of the next correction,
  with ``k = SolverOptions.first_edit_sigma`` during the first ``warmup`` linearisations
  (only gross errors: a poor first guess has large residuals everywhere) and then
  ``edit_sigma * max(1, previous weighted RMS)`` (3.5 sigma once the fit is good); editing is
  re-decided at every iteration (an edited measurement can come back), and never more than
  ``max_reject_fraction`` of the measurements are edited (the worst ones);
* a correction that does not reduce the weighted sum of squares (over the measurements it
  was computed from) is halved, up to ``max_halvings`` times (a damped Gauss-Newton: from the
  filter's estimate, or 10 km and 10 m/s off, the fit converges in 4-7 linearisations);
* convergence: the accepted set did not change and either the last correction was below
  ``correction_tol`` in units of its own formal sigma (``sqrt(dx^T N dx / n)``), or the
  weighted RMS changed by less than ``rms_rtol`` relative, or it is round-off (below 1e-8:
  noise-free data). Divergence: a non-finite residual or trajectory, a state that is no
  Earth orbit (`initiation.earth_orbit_problem`) at the first guess or after every halving,
  or weighted residuals that grow along the correction however short the step. Singular
  normal equations or too few measurements are `FitStatus.UNDERDETERMINED`;
  ``max_iterations`` corrections end a slow fit (`FitStatus.MAX_ITERATIONS`). Every outcome
  is a `FitStatus` with a reason, never an exception.

The weighted RMS is ``sqrt(mean(r_w^2))`` over the accepted measurements' whitened residual
channels: 1 for a fit whose residuals are the noise R says.

Covariances
    ``P`` is the formal covariance of the solve-for vector (state at the epoch, then the
    solved parameters): ``(J^T J + prior information)^-1`` of the last linearisation.
    ``P_realistic`` adds what the formal one leaves out, each term stated in
    `BatchOptions`:

    * *consider parameters* (``consider``, standard deviations ``param_sigma``): force-model
      parameters not solved for but uncertain (e.g. the drag factor of a J2 + drag fit,
      or RTN accelerations standing for unmodelled forces); their effect on the estimate,
      ``S_xc = P J^T J_c`` per unit, gives ``S_xc P_cc S_xc^T``, and through a prediction
      ``(G S_xc - Psi) P_cc (G S_xc - Psi)^T`` with ``Psi = d x(t) / d c``;
    * *process noise through the window* (``snc_psd``, state-noise compensation in RTN,
      `process_noise.snc` on a grid of ``noise_step_s`` along the reference trajectory):
      white accelerations between the measurements and the epoch make the measurements'
      errors correlated, ``cov(e_i, e_j) = H_i Phi_i C(min(i, j)) Phi_j^T H_j^T`` with
      ``C`` the noise accumulated from the epoch outwards in epoch coordinates, and give the
      estimate ``P (J^T C_e J) P``; through a prediction the same noise accumulates from
      the epoch on (independent of the window's, for predictions after the epoch; into the
      window, the epoch's covariance mapped back plus that noise: conservative;
      `window_noise`);
    * optionally (``scale_by_rms``) the formal part scaled by the weighted RMS squared when
      it exceeds 1 (the a-posteriori variance factor).

Prediction: `BatchFit.predict` gives the state and covariance (formal or realistic) at any
epochs, integrating once from the epoch; `grid` gives the 60 s epochs of a gap.

Cost (`bench/bench_batch_ls.py`): three passes of one radar (~90 range/az/el), J2 or J2 +
drag with its factor: 6-10 ms a fit (3-5 linearisations), ~20 ms when the three passes
span a day; the prediction through a gap on the 60 s grid with the realistic covariance,
~1 ms.

Units: km, km/s, rad, s; states GCRF; times in s on the measurements' clock (Unix s UTC,
`BatchOptions.clock_unix0` otherwise).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ssa_fusion.core.base.types import Measurement, StateEstimate
from ssa_fusion.core.earth import frames
from ssa_fusion.core.filter.initiation import earth_orbit_problem
from ssa_fusion.core.motion.force_model import (
    NOMINAL,
    PARAMETERS,
    ForceModel,
    parameter_index,
    trajectory,
)
from ssa_fusion.core.motion.force_spec import ForceSpec
from ssa_fusion.core.od.fit_window import FitModel, FitWindow
from ssa_fusion.core.od.gauss_newton import (
    FitStatus,
    Linearization,
    Solution,
    SolverOptions,
    gauss_newton,
)
from ssa_fusion.core.od.window_noise import accumulated_noise, window_noise, with_grid

__all__ = ["BatchFit", "BatchOptions", "FitStatus", "Linearization", "Solution",
           "SolverOptions", "fit", "gauss_newton", "grid", "whitened_predictions",
           "whitened_residuals"]

Array = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]


# --------------------------------------------------------------------------------------------
# The orbit
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class BatchOptions:
    """The orbit fit: force model, solve-for and consider parameters, noise, solver.

    Attributes
    ----------
    force : ForceModel or ForceSpec
        Gravity (two-body + J2) and optional drag (`force_model`), or the high-fidelity
        model (`force_spec.ForceSpec`: geopotential, Sun, Moon, tides, SRP; the
        measurements' clock must then be Unix s UTC, ``clock_unix0`` 0).
    solve_for : tuple of str
        Parameters estimated with the state (`force_model.PARAMETERS`): ``drag_scale``
        (needs ``force.drag``), ``accel_r``, ``accel_t``, ``accel_n``, ``srp_scale`` (a
        factor on Cr: needs a `ForceSpec` with ``srp``).
    consider : tuple of str
        Parameters not estimated whose uncertainty goes into the realistic covariance.
    param_sigma : tuple of float
        A-priori standard deviations of the parameters (`PARAMETERS` order:
        dimensionless, km/s^2 x 3, dimensionless): the prior of the solved ones (inf:
        none), the uncertainty of the considered ones (the first four suffice without
        ``srp_scale``). The measurement model's own parameters (a laser network's range
        biases) take the priors it holds.
    snc_psd : tuple of 3 float
        State-noise compensation PSDs along R, T, N, km^2/s^3, of the realistic covariance
        (through the window and the predictions); 0: none.
    scale_by_rms : bool
        Scale the formal part of the realistic covariance by max(1, RMS^2).
    max_step_s : float
        Longest integration step, s.
    noise_step_s : float
        Grid of the process noise's mapping, s.
    clock_unix0 : float
        Unix time (s, UTC) of t = 0 of the measurements' clock (0: stamps are Unix s), for
        the Earth's pole.
    solver : SolverOptions
        Iterations, editing and convergence.
    """

    force: ForceModel | ForceSpec = field(default_factory=ForceModel)
    solve_for: tuple[str, ...] = ()
    consider: tuple[str, ...] = ()
    param_sigma: tuple[float, ...] = (1.0, 1e-8, 1e-8, 1e-8, 1.0)
    snc_psd: tuple[float, float, float] = (0.0, 0.0, 0.0)
    scale_by_rms: bool = False
    max_step_s: float = 60.0
    noise_step_s: float = 60.0
    clock_unix0: float = 0.0
    solver: SolverOptions = field(default_factory=SolverOptions)

    def __post_init__(self) -> None:
        """Check the parameter names (ValueError naming the problem)."""
        parameter_index(self.solve_for)
        parameter_index(self.consider)
        if set(self.solve_for) & set(self.consider):
            raise ValueError("a parameter cannot be both solved for and considered: "
                             f"{sorted(set(self.solve_for) & set(self.consider))}")
        used = (*self.solve_for, *self.consider)
        if "drag_scale" in used and not self.force.drag:
            raise ValueError("drag_scale needs a force model with drag (ForceModel.drag)")
        if "srp_scale" in used and getattr(self.force, "srp", None) is None:
            raise ValueError("srp_scale needs the high-fidelity model with SRP (ForceSpec.srp)")
        if any(PARAMETERS.index(p) >= len(self.param_sigma) for p in used):
            raise ValueError(f"param_sigma has {len(self.param_sigma)} values: "
                             f"{len(PARAMETERS)} needed ({', '.join(PARAMETERS)})")

    def sigma(self, names: Sequence[str]) -> Array:
        """Return the ``param_sigma`` of the parameters ``names``."""
        return np.array([self.param_sigma[i] for i in parameter_index(names)], dtype=float)


@dataclass
class BatchFit:
    """The result of `fit`: the epoch state, parameters, covariances and residuals.

    Attributes
    ----------
    status, reason, iterations, rms, rms_history
        As `Solution` (module docstring).
    t : float
        The epoch, s.
    x : ndarray (6,)
        GCRF state at ``t``, km, km/s.
    params : dict of str to float
        Every force-model parameter (`PARAMETERS`): the solved ones estimated, the others
        nominal.
    solve_for : tuple of str
        The solved force-model parameters, in the order of the solve-for vector after the
        state.
    P, P_realistic : ndarray (n, n)
        Formal and realistic covariance of [state, solved force-model parameters,
        measurement parameters] (module docstring).
    t_meas : ndarray (N,)
        The measurements' epochs, in the order given.
    residuals : list of ndarray
        ``z - h(x)`` of each measurement at the last linearisation (angles wrapped), in its
        units (km, rad).
    normalized : ndarray (N,)
        Largest whitened residual channel of each measurement (absolute, sigma units).
    accepted : ndarray (N,) of bool
        False for a measurement edited out.
    options : BatchOptions
        The options of the fit.
    pole : ndarray (3,)
        The Earth's pole used (GCRF unit vector).
    measurement_params : dict of str to float
        The measurement model's solved parameters (a laser network's range biases, km), in
        the order of the solve-for vector after the force-model parameters.
    """

    status: FitStatus
    reason: str
    iterations: int
    rms: float
    rms_history: list[float]
    t: float
    x: Array
    params: dict[str, float]
    solve_for: tuple[str, ...]
    P: Array
    P_realistic: Array
    t_meas: Array
    residuals: list[Array]
    normalized: Array
    accepted: BoolArray
    options: BatchOptions
    pole: Array
    measurement_params: dict[str, float] = field(default_factory=dict)
    _sxc: Array = field(repr=False, default_factory=lambda: np.zeros((6, 0)))
    _P_base: Array = field(repr=False, default_factory=lambda: np.zeros((6, 6)))

    @property
    def converged(self) -> bool:
        """True when the fit converged (`FitStatus.CONVERGED`)."""
        return self.status == FitStatus.CONVERGED

    @property
    def covariance(self) -> Array:
        """Formal covariance (6, 6) of the epoch state, km^2, km^2/s, km^2/s^2 (GCRF)."""
        return self.P[:6, :6].copy()

    @property
    def covariance_realistic(self) -> Array:
        """Realistic covariance (6, 6) of the epoch state (module docstring), GCRF."""
        return self.P_realistic[:6, :6].copy()

    @property
    def names(self) -> tuple[str, ...]:
        """The solve-for vector's parameters after the state (P's rows 6..)."""
        return (*self.solve_for, *self.measurement_params)

    def sigma(self, name: str, realistic: bool = False) -> float:
        """Return the standard deviation of solved parameter ``name`` (formal, realistic)."""
        i = 6 + self.names.index(name)
        return float(math.sqrt((self.P_realistic if realistic else self.P)[i, i]))

    def estimate(self, realistic: bool = True, object_id: str = "") -> StateEstimate:
        """Return the epoch state as a `types.StateEstimate` (GCRF km, km/s)."""
        P = self.covariance_realistic if realistic else self.covariance
        return StateEstimate(self.t, self.x.copy(), P, object_id)

    def predict(self, t: ArrayLike, realistic: bool = True) -> tuple[Array, Array]:
        """Return the fitted orbit's states and covariances at the epochs ``t``.

        Parameters
        ----------
        t : array_like (K,)
            Epochs, s (either side of the epoch, any order).
        realistic : bool
            The realistic covariance mapped with its consider parameters and the process
            noise accumulated from the epoch (module docstring); False: the formal one.

        Returns
        -------
        (x (K, 6) GCRF km, km/s; P (K, 6, 6) km^2, km^2/s, km^2/s^2).
        """
        o = self.options
        tt = np.atleast_1d(np.asarray(t, dtype=float))
        psd = np.asarray(o.snc_psd, dtype=float)
        noise = realistic and bool(np.any(psd > 0.0))
        epochs = with_grid(self.t, tt, o.noise_step_s) if noise else tt
        cons = list(o.consider) if realistic else []
        which = parameter_index((*self.solve_for, *cons))
        prm = np.array([self.params[p] for p in PARAMETERS])
        tr = trajectory(o.force, self.x, self.t, epochs, prm, which.tolist(), o.max_step_s,
                        self.pole)
        ns = len(self.solve_for)
        k = 6 + ns  # the measurement parameters do not move the orbit
        G = np.concatenate([tr.phi, tr.s[:, :, :ns]], axis=2)
        base = (self._P_base if realistic else self.P)[:k, :k]
        P = G @ base @ np.swapaxes(G, 1, 2)
        if cons:
            m = G @ self._sxc[:k] - tr.s[:, :, ns:]
            sc = _consider_sigma(o)
            P += (m * sc * sc) @ np.swapaxes(m, 1, 2)
        if noise:
            P += accumulated_noise(self.t, epochs, tr.x, tr.phi, psd)
        pos = np.searchsorted(epochs, tt) if noise else np.arange(tt.size)
        x_out: Array = tr.x[pos]
        P_out = P[pos]
        P_out = 0.5 * (P_out + np.swapaxes(P_out, 1, 2))
        return x_out, P_out

    def estimates(self, t: ArrayLike, realistic: bool = True,
                  object_id: str = "") -> list[StateEstimate]:
        """Return `predict` at the epochs ``t`` as `types.StateEstimate` (GCRF)."""
        tt = np.atleast_1d(np.asarray(t, dtype=float))
        x, P = self.predict(tt, realistic)
        return [StateEstimate(float(ti), xi, Pi, object_id)
                for ti, xi, Pi in zip(tt, x, P, strict=True)]


def grid(t_from: float, t_to: float, step_s: float = 60.0) -> Array:
    """Return the multiples of ``step_s`` in (``t_from``, ``t_to``], s: a gap's epochs.

    The 60 s grid on which the filter publishes its predictions through a gap
    (`tracker.prediction_epochs` without a limit).
    """
    k0, k1 = math.floor(t_from / step_s) + 1, math.floor(t_to / step_s)
    out: Array = np.arange(k0, k1 + 1, dtype=float) * step_s
    return out


def _consider_sigma(o: BatchOptions) -> Array:
    """Return the consider parameters' standard deviations (in the order of ``o.consider``)."""
    return o.sigma(o.consider)


def whitened_residuals(measurements: Sequence[Measurement], model: FitModel,
                       x: ArrayLike) -> Array:
    """Return each measurement's squared whitened residual against the states ``x`` (N, 6).

    ``(z - h(x))^T R^-1 (z - h(x))`` per measurement (angles wrapped), ``x`` GCRF states at
    the measurements' epochs: chi2 with len(z) degrees of freedom for a right state.
    ValueError for a measurement the model cannot predict.
    """
    w = FitWindow(measurements, model)
    r, _, _ = w.residuals(np.asarray(x, dtype=float).reshape(-1, 6),
                          np.zeros((len(w.m), 6, 1)))  # no unknowns: one zero column
    out: Array = np.asarray(np.bincount(w.rows(), weights=r * r, minlength=len(w.m)), float)
    return out


def whitened_predictions(measurements: Sequence[Measurement], model: FitModel,
                         x: ArrayLike, P: ArrayLike) -> tuple[Array, Array]:
    """Return the predicted measurements' misfit in the whitened eigenbasis of their covariance.

    For each measurement, with ``W`` the inverse Cholesky factor of its R: the whitened
    residual ``r = W (z - h(x))`` and the whitened predicted covariance ``S = W H P H^T W^T``
    (``x`` (N, 6), ``P`` (N, 6, 6) GCRF states and covariances at their epochs). Returned
    flat over every measurement's channels: ``lam`` the eigenvalues of its ``S`` and ``q2``
    the squared components of ``r`` along their eigenvectors, so that the NIS with the
    prediction's covariance scaled by k is ``sum(q2 / (k lam + 1))``.
    ValueError for a measurement the model cannot predict.
    """
    w = FitWindow(measurements, model)
    cov = np.asarray(P, dtype=float).reshape(-1, 6, 6)
    vals, vecs = np.linalg.eigh(0.5 * (cov + np.swapaxes(cov, 1, 2)))
    root = vecs * np.sqrt(np.maximum(vals, 0.0))[:, None, :]  # root root^T = P
    r, J, _ = w.residuals(np.asarray(x, dtype=float).reshape(-1, 6), root)
    J = J[:, :6]  # the state's columns (no measurement parameter here)
    rows = w.rows()
    lam, q2 = [], []
    for i in range(len(w.m)):
        mine = rows == i
        e, v = np.linalg.eigh(J[mine] @ J[mine].T)
        lam.append(np.maximum(e, 0.0))
        q2.append((v.T @ r[mine]) ** 2)
    return np.concatenate(lam), np.concatenate(q2)


def fit(measurements: Sequence[Measurement], model: FitModel, x_guess: ArrayLike,
        t_guess: float, options: BatchOptions | None = None, epoch: float | None = None,
        prior_cov: ArrayLike | None = None) -> BatchFit:
    """Fit an orbit (and the solve-for parameters) to a window of measurements.

    Parameters
    ----------
    measurements : sequence of Measurement
        The window (real measurements; any order): range/az/el or ra/dec with the station
        in ``frame_id``, GCRF positions, or laser ranges, stamped on the clock of ``model``.
    model : MeasurementModel or LaserModels
        The measurement model(s) (`config.measurement_model`: a station network's
        `measurement.StationModels`, one station's model, a `measurement.PositionModel`;
        or a laser network's `laser_model.LaserModels`, whose stations' range biases are
        then solved for too, each with its prior).
    x_guess : array_like (6,)
        First guess of the GCRF state (km, km/s) at ``t_guess`` (e.g. the filter's estimate).
    t_guess : float
        Its epoch, s.
    options : BatchOptions, optional
        Force model, parameters, noise and solver.
    epoch : float, optional
        Epoch of the estimated state, s (default: the last measurement's).
    prior_cov : array_like (6, 6), optional
        Covariance of ``x_guess`` to use as a-priori information (mapped to the epoch);
        None: the state has no prior (only the data).

    Returns
    -------
    BatchFit
        Also when the fit did not converge (`BatchFit.status`, `BatchFit.reason`).
    """
    o = options or BatchOptions()
    win = FitWindow(measurements, model)
    if not win.m:
        raise ValueError("no measurements to fit")
    t0 = float(np.max(win.t)) if epoch is None else float(epoch)
    pole = frames.pole_frame(t0 + o.clock_unix0)[2].copy()
    solve, cons = parameter_index(o.solve_for), parameter_index(o.consider)
    which = np.concatenate([solve, cons]).tolist()
    ns, nc = solve.size, cons.size
    n = 6 + ns + len(win.params)
    base = np.array(NOMINAL, dtype=float)
    mean, info = _prior(o, win, x_guess, float(t_guess), t0, prior_cov, pole)
    rows = win.rows()
    last: dict[str, object] = {}

    def evaluate(v: Array) -> Linearization | str:
        problem = earth_orbit_problem(v[:6])
        if problem:
            return f"the state is no Earth orbit ({problem})"
        prm = base.copy()
        prm[solve] = v[6:6 + ns]
        tr = trajectory(o.force, v[:6], t0, win.t, prm, which, o.max_step_s, pole)
        if not tr.ok.all():
            return "the trajectory is not finite"
        G = np.concatenate([tr.phi, tr.s], axis=2)
        r, J, raw = win.residuals(tr.x, G, v[6 + ns:])
        # [state, solved, measurement parameters | considered]
        J = np.concatenate([J[:, :6 + ns], J[:, 6 + ns + nc:], J[:, 6 + ns:6 + ns + nc]], 1)
        lin = Linearization(r, J[:, :n], rows, len(win.m))
        last.update(lin=lin, J=J, raw=raw)  # the partials of the consider parameters too
        return lin

    sol = gauss_newton(evaluate, mean, o.solver, mean, info if info.any() else None)
    if last.get("lin") is not sol.lin or sol.lin is None:  # a rejected trial step was last
        last.clear()
    out = _result(sol, o, win, t0, pole, last.get("raw"), solve, nc)
    J_full = last.get("J")
    if sol.lin is not None and isinstance(J_full, np.ndarray) and np.isfinite(sol.P).all():
        _realistic(out, win, J_full, sol, n, ns)
    return out


def _prior(o: BatchOptions, win: FitWindow, x_guess: ArrayLike, t_guess: float, t0: float,
           prior_cov: ArrayLike | None, pole: Array) -> tuple[Array, Array]:
    """Return the first guess of the solve-for vector at ``t0`` and its prior information.

    The state's information is that of ``prior_cov`` mapped to ``t0`` (none without); the
    force-model parameters' that of ``param_sigma``, the measurement parameters' their
    model's priors (a sigma of inf or 0: no information).
    """
    solve = parameter_index(o.solve_for)
    base = np.array(NOMINAL, dtype=float)
    xg = np.asarray(x_guess, dtype=float).reshape(6)
    prior_x = None
    if t_guess != t0:
        g = trajectory(o.force, xg, t_guess, [t0], base, (), o.max_step_s, pole)
        xg, prior_x = g.x[0], g.phi[0]
    sig = np.concatenate([o.sigma(o.solve_for), win.prior_sigma])
    n = 6 + sig.size
    info = np.zeros((n, n))
    info[6:, 6:] = np.diag(np.where(np.isfinite(sig) & (sig > 0), 1.0 / sig**2, 0.0))
    if prior_cov is not None:
        pc = np.asarray(prior_cov, dtype=float)
        if prior_x is not None:
            pc = prior_x @ pc @ prior_x.T
        info[:6, :6] = np.linalg.inv(0.5 * (pc + pc.T))
    return np.concatenate([xg, base[solve], win.prior_mean]), info


def _result(sol: Solution, o: BatchOptions, win: FitWindow, t0: float, pole: Array,
            raw: object, solve: IntArray, nc: int) -> BatchFit:
    """Return the `BatchFit` of a solution (its realistic covariance still the formal one)."""
    ns = solve.size
    params = dict(zip(PARAMETERS, NOMINAL, strict=True))
    for j, i in enumerate(solve):
        params[PARAMETERS[int(i)]] = float(sol.x[6 + j])
    residuals = (list(raw) if isinstance(raw, list)
                 else [np.full(len(m.z), math.nan) for m in win.m])
    n = 6 + ns + len(win.params)
    return BatchFit(sol.status, sol.reason, sol.iterations, sol.rms, sol.rms_history, t0,
                    sol.x[:6].copy(), params, tuple(o.solve_for), sol.P, sol.P.copy(),
                    win.t, residuals,
                    sol.score if sol.score.size == len(win.m) else np.full(len(win.m), np.nan),
                    sol.accepted if sol.accepted.size == len(win.m)
                    else np.zeros(len(win.m), dtype=bool), o, pole,
                    dict(zip(win.params, sol.x[6 + ns:].tolist(), strict=True)),
                    np.zeros((n, nc)), sol.P.copy())


def _realistic(out: BatchFit, win: FitWindow, J_full: Array, sol: Solution, n: int,
               ns: int) -> None:
    """Fill ``out``'s realistic covariance: consider parameters, process noise, RMS scale."""
    o = out.options
    assert sol.lin is not None
    rows = sol.accepted[sol.lin.group]
    J = J_full[rows]
    P = sol.P
    scale = max(1.0, sol.rms**2) if o.scale_by_rms else 1.0
    base = scale * P
    psd = np.asarray(o.snc_psd, dtype=float)
    if np.any(psd > 0.0):
        prm = np.array([out.params[p] for p in PARAMETERS])
        base = base + P @ window_noise(o.force, out.x, out.t, prm, o.max_step_s, out.pole,
                                       o.noise_step_s, win.t, J[:, :n], sol.lin.group[rows],
                                       psd) @ P
    out._P_base = 0.5 * (base + base.T)
    real = out._P_base.copy()
    if o.consider:
        sxc = P @ J[:, :n].T @ J[:, n:]
        sc = _consider_sigma(o)
        out._sxc = sxc
        real += (sxc * sc * sc) @ sxc.T
    out.P_realistic = 0.5 * (real + real.T)


