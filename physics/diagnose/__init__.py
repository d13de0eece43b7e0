"""Diagnosis: see where a model fails, learn which physical effect is missing, add it,
watch the error fall — with statistics that do not cry wolf.

::

    from physics.diagnose import diagnose, write_diagnosis
    res = diagnose(["sweep.csv", "pulse.csv"], "ipmc_pt_eg", "none")
    res.verdict.missing_effect, res.verdict.confidence
    [(c.effect, c.comparison.delta_bic) for c in res.ranking]
    write_diagnosis(res, "runs/diagnose", apply=True)

Modules: :mod:`.records` (records, decimation, noise floor), :mod:`.candidates` (specs,
fits, time-domain scores), :mod:`.describing` (describing function of the large-signal
double layer), :mod:`physics.analysis.stats` (effective sample size, BIC, p-values), :mod:`.residuals`
(where it fails), :mod:`.signatures` (what each effect leaves behind, what data reveal it),
:mod:`.diagnosis` (the driver and the verdict), :mod:`.report` (JSON, PNG, HTML, device
file).  Synthetic measurements with a hidden effect are outside the core, in
:mod:`physics.testbeds`.
"""
from .diagnosis import AnalysisOptions, DiagnosisResult, SelectionOptions, Verdict, diagnose
from .report import write_diagnosis
from .specs import excitation

__all__ = ["diagnose", "AnalysisOptions", "DiagnosisResult", "SelectionOptions", "Verdict", "write_diagnosis",
           "excitation"]
