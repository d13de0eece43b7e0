"""Signal analysis on records, independent of the actuator model: FRF estimation
(:mod:`.frf_estimation`), error metrics (:mod:`.metrics`), statistics (:mod:`.stats`:
effective sample size, information criteria, tests).

Floor: next to the ground floor; imports no solver and no effect.
"""
