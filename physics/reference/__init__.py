"""Reference solver of the thesis equations (eq. 1–8) for validating the reduced model.

- :mod:`physics.reference.pnp`: nonlinear Poisson–Nernst–Planck + solvent transport through
  the thickness (graded finite volumes, Scharfetter–Gummel fluxes, TR-BDF2 with banded Newton),
  and its linearisation in the frequency domain;
- :mod:`physics.reference.strip`: slabs along the strip through the electrode resistance, the
  load definition that makes it comparable with the reduced model, the shared beam;
- :mod:`physics.reference.validate`: the validation report (``eap validate``).
"""
from .pnp import Integrator, Slab, SlabParams, Tolerances, graded_mesh
from .strip import ReferenceResult, ReferenceStrip

__all__ = ["Integrator", "ReferenceResult", "ReferenceStrip", "Slab", "SlabParams", "Tolerances", "graded_mesh"]
