"""Solvers of the actuator model: the frequency response (:mod:`.frequency`), time-domain
simulation (:mod:`.timedomain`, stepped in :mod:`.stepper`, linear state space in :mod:`.lti`
and :mod:`.realize`), the beam (:mod:`.beam`, :mod:`.discretisation`) and parameter sweeps (:mod:`.sweep`).

Floor: above the effects and the device; below compare, identify, diagnose and reference.
"""
