"""Constants of the identification: the thesis procedure and the identifiability limits."""
#: Thesis cost of one model evaluation: COMSOL, 15 min per frequency (docs/reference/physics.md).
THESIS_SECONDS_PER_FREQUENCY = 15 * 60.0
#: Thesis Nelder–Mead settings (ch. 1 §5).
THESIS_MAX_ITER = 100
THESIS_TOL = 1e-6

REL_SE_LIMIT = 0.5        # relative standard error above which a parameter is flagged
CORR_LIMIT = 0.98         # |correlation| above which a pair is flagged
COND_LIMIT = 1e7          # condition number of J above which JᵀJ is near-singular
EPS_FLOOR = 1e-4          # floor of the relative random error used as weight
DEFAULT_DECADES = 3.0     # default search range either side of the start (log parameters)

#: Why a parameter may have no effect, by name (shown when it is refused).
