"""Model against measurement: time overlays, frequency responses, metrics and a report.

**One contract for every model.**  A *predictor* answers "what tip deflection [m] does
this voltage record [V], sampled at ``fs`` [Hz] at relative humidity ``rh`` [%] (a
constant or one value per sample), produce?"::

    y = predictor(voltage, rh, fs)

:class:`PhysicsPredictor` wraps an :class:`~physics.model.ActuatorModel` (and also offers
its closed-form small-signal frequency response); :class:`CallablePredictor` wraps any
function with that signature — the command line uses it for trained neural-model bundles
(``nnmodel.load(path).predict``), so that :mod:`physics` never imports :mod:`nnmodel`.
A predictor without a closed-form response is compared in frequency through the same
H1 estimate applied to its simulated output.

**What :func:`compare` computes** for each time-series record (``docs/reference/file-formats.md``):

* the model's output for the measured voltage and RH; time metrics of
  :mod:`physics.analysis.metrics` — RMSE [m], NRMSE, fit % = 100 (1 − ‖y − ŷ‖/‖y − ȳ‖) (MATLAB
  ``compare``), Pearson correlation (the thesis reports 98 % for the IP2C at 0.2 Hz) —
  after removing the best constant offset (a laser sensor's zero is arbitrary;
  ``offset="none"`` keeps it) and an optional start-up interval ``skip_s``;
* the H1 frequency-response estimate of the measurement and, with the same estimator,
  of the model output (:func:`physics.analysis.frf_estimation.estimate_frf`; settings chosen from
  the record's excitation, see :class:`FRFOptions`), plus the model's closed form;
* the thesis identification cost J_err of eq. 13 (De Luca 2014),
  sqrt(Σ_i (|δ_exp(f_i)| − |δ_sim(f_i)|)²/N) [m/V], on the excited frequencies whose
  coherence reaches ``min_coherence``, with |δ_sim| the closed form when the model has
  one (as in the thesis, where COMSOL solved each frequency) and otherwise the estimate
  from the simulated output; the log-magnitude [dB] and phase [deg] RMS errors;
* errors by frequency band: the residual's RMS and its NRMSE within the band (from the
  spectrum of the residual, Parseval) and the FRF errors within the band;
* errors by RH: records grouped by their mean RH (within ``rh_tolerance`` %).

Frequency-response files (``freq_Hz, mag_m_per_V, phase_deg``…) are compared with the
closed form of a physics predictor at the file's RH.

RH given to the model: a record's RH channel is noisy; when it spans at most
``rh_tolerance`` % the model gets its median (robust to a sensor clipped at 100 %),
otherwise a 10-s moving mean rounded to 0.5 % (:func:`model_rh`).

Known sensor dynamics are part of the measurement, not of the actuator: with
``sensor_bandwidth="auto"`` a first-order sensor low-pass recorded in a record's
metadata (``meta["sensor"]["bandwidth"]``, written by :class:`physics.io.sensor.SensorModel`)
is applied to the model output before comparing; give a number [Hz] or ``None``.
"""

from __future__ import annotations

from .predictors import CallablePredictor, PhysicsPredictor, Predictor
from .measurements import check_measurements, cluster_rh, is_frf_file, load_measurements, mean_rh, model_rh, source_name
from .frf import FRFOptions, default_bands, estimate_record_frf, frf_errors, parse_bands, residual_by_band, sensor_bandwidth_of, sensor_lowpass, sensor_response, thin_log, valid_points
from .comparison import ComparisonResult, RecordComparison, compare
from .report import plot_time_overlay, write_comparison_report

__all__ = ["CallablePredictor", "ComparisonResult", "FRFOptions", "PhysicsPredictor", "Predictor", "RecordComparison", "check_measurements", "cluster_rh", "compare", "default_bands", "estimate_record_frf", "frf_errors", "is_frf_file", "load_measurements", "mean_rh", "model_rh", "parse_bands", "plot_time_overlay", "residual_by_band", "sensor_bandwidth_of", "sensor_lowpass", "sensor_response", "source_name", "thin_log", "valid_points", "write_comparison_report"]
