"""Parameter identification from measurements, with honest uncertainty.

Given measurements (time-series records and/or frequency-response files), a device
with a set of effects and the names of the free parameters, :func:`identify` finds the
parameter values that make the model reproduce the measured frequency response.

**Data.**  Each time record is turned into an H1 frequency-response estimate
(:func:`physics.compare.estimate_record_frf`, settings from its excitation; excited
frequencies with coherence ≥ ``min_coherence``, thinned to about ``max_points``
log-spaced lines); frequency-response files are used as they are.  Known sensor
dynamics (a first-order low-pass, see :mod:`physics.compare`) multiply the model.

**Methods.**

``"nelder-mead"`` — the thesis procedure, reproducible (De Luca 2014, ch. 1 §5):
    Nelder–Mead simplex (Nelder & Mead, Computer Journal 7:308, 1965;
    :func:`scipy.optimize.minimize`, the algorithm of MATLAB ``fminsearch``) on the cost
    of eq. 13, J_err = sqrt(Σ_i (|δ_exp(f_i)| − |δ_sim(f_i)|)²/N), FRF magnitudes only,
    at most 100 iterations, tolerance 1e-6 on parameters and cost.  The thesis does not
    say in which units the tolerance applies; here the parameters are divided by their
    start values (the initial simplex is the start plus 5 % of each component, as in
    ``fminsearch``; 0.00025 for a zero start) and J_err by the RMS measured magnitude, so
    both tolerances are relative and unit-independent.  Bounds clip the simplex.

``"lsq"`` (default) — bounded nonlinear least squares (:func:`scipy.optimize.least_squares`,
    trust-region reflective) on the complex FRF: the residual at frequency f_i is
    w_i · ln(Ĥ_model(f_i)/Ĥ_meas(f_i)), whose real part is the log-magnitude error and
    imaginary part the (wrapped) phase error in rad — the two are on the same relative
    scale.  With ``weighting="coherence"`` w_i = 1/ε_i, ε the Bendat–Piersol random error
    of the H1 estimate (std of ln|Ĥ| and of the phase; median-smoothed over 9 lines,
    floored at 1e-4), so the weighted residuals are about N(0, 1); without coherence (or
    with ``"uniform"``) w_i = 1.  ``residual="time"`` fits the time records instead
    (simulated output minus measurement, best offset removed, in units of the
    measurement's standard deviation); ``"both"`` stacks the two blocks, each scaled to
    the same total weight.  Parameters are searched in log space (ln θ; fractional
    orders and other dimensionless quantities bounded within [0, 1] in linear space)
    within bounds from the parameter specifications, narrowed by default to three
    decades either side of the start.  Multi-start: the start plus ``n_starts − 1``
    Latin-hypercube points within ``start_spread`` decades of it (the whole range for
    linear parameters); the lowest cost wins and every start is reported.

**Uncertainty** (Bates & Watts, *Nonlinear Regression Analysis and its Applications*,
Wiley 1988, §2.3; linear approximation at the optimum).  With the weighted residual
vector r (n values) and its Jacobian J = ∂r/∂x in the search coordinates x (central
differences), the residual variance s² = ‖r‖²/(n − p) scales the covariance

    Cov(x̂) = s² (JᵀJ)⁻¹,    computed as s² V S⁻² Vᵀ from the SVD J = U S Vᵀ,

so the standard errors are right whatever the absolute level of the weights (and s²
itself — the reduced chi-square — should be ≈ 1 with coherence weights when the model is
adequate).  For a log parameter the standard error of θ is θ·se(ln θ) (delta method) and
the 95 % interval θ·exp(±t se) (Student t, n − p degrees of freedom); for a linear one
θ ± t se.  Time residuals are autocorrelated: their covariance is multiplied by the
integrated autocorrelation time of the residuals (effective number of independent
samples).  Correlations are Cov_ij/sqrt(Cov_ii Cov_jj).  A parameter is flagged **not
identifiable** (an :class:`IdentifiabilityWarning`, also listed in the result) when its
relative standard error exceeds 50 %, when a correlation exceeds 0.98 in magnitude
(only a combination is determined), when JᵀJ is near-singular (condition number of J
above 1e7; the parameters in the weakest direction are named) or when it ends on a bound
(its interval is then not meaningful).  A parameter that does not change the frequency
response at all is refused before an FRF fit (:class:`~physics.errors.InputError`).

**Humidity (joint fits).**  Records at several RH levels (grouped within
``rh_tolerance`` %) are fitted together.  Two designs, which can be combined:

* ``free``: one value shared by all records.  With the ``humidity`` effect on and a
  ``ratio`` map for that parameter in the device (Table V as shipped), the value fitted
  is the one at the device's reference RH and the map's shape carries it to every RH.
* ``per_rh``: Table V style — one free value of the parameter at each RH level present in
  the data.  They become an ``absolute`` humidity map of that parameter with the data's
  RH levels as nodes (replacing any map it had), so the model at level k uses exactly
  the k-th value; between levels it is interpolated linearly, outside held at the ends.
  Needs the ``humidity`` effect and records at two or more RH levels.  For ``Y`` the map
  scales whichever modulus is active (an absolute ``Y`` value divided by the device's
  ``Y``, e.g. the DMA table with ``viscoelastic``), for ``kf`` it scales ``kf0`` as well.

:func:`write_identification` writes the fitted device (same schema as
``configs/devices/*.yaml``, each identified value with its unit and a source "identified
by eap identify from FILES on DATE"), ``report.json``, CSV tables, PNGs and one
self-contained HTML page.
"""

from __future__ import annotations

from .devicefile import identified_device_raw, write_device
from .fitting import Fit, fit_lsq, fit_nelder_mead, jacobian, uncertainty
from .options import FitOptions, LsqOptions
from .free_parameters import FreeParameter, IdentifiabilityWarning, parse_assignments, parse_names
from .problem import FRFTarget, IdentificationProblem, build_targets
from .report import write_identification
from .result import IdentificationResult, identify
from .settings import (CORR_LIMIT, COND_LIMIT, REL_SE_LIMIT, THESIS_MAX_ITER, THESIS_SECONDS_PER_FREQUENCY,
                       THESIS_TOL)

__all__ = ["CORR_LIMIT", "COND_LIMIT", "Fit", "FitOptions", "FRFTarget", "FreeParameter", "IdentifiabilityWarning",
           "IdentificationProblem", "IdentificationResult", "LsqOptions", "REL_SE_LIMIT", "THESIS_MAX_ITER",
           "THESIS_SECONDS_PER_FREQUENCY", "THESIS_TOL", "build_targets", "fit_lsq", "fit_nelder_mead",
           "identified_device_raw", "identify", "jacobian", "parse_assignments", "parse_names", "uncertainty",
           "write_device", "write_identification"]
