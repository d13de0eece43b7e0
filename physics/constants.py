"""Physical constants (CODATA 2018, exact SI values where defined)."""

FARADAY = 96485.33212          # C/mol
GAS_CONSTANT = 8.314462618     # J/(mol K)
EPS0 = 8.8541878128e-12        # F/m
AVOGADRO = 6.02214076e23       # 1/mol
T_REF = 298.15                 # K, 25 degC, the thesis's chamber temperature
