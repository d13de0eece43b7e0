"""Pages and plots: the self-contained HTML page (:mod:`.report`), figures (:mod:`.plotting`,
matplotlib imported on first use) and table columns with units (:mod:`.columns`).

Floor: presentation.  Only the page writers (``compare.report``, ``identify.report``,
``diagnose.report``, ``reference.validate``'s plots) and the application import it; solvers,
effects, I/O and analysis never do (``tests/test_architecture.py``).
"""
