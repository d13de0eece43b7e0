"""Measurement and file I/O: CSV tables (:mod:`.csvtable`), time records (:mod:`.timeseries`,
:mod:`.record`) with their sidecars (:mod:`.sidecar`), measured FRFs (:mod:`.frfdata`), YAML
(:mod:`.yamlio`), units (:mod:`.units`), sensors (:mod:`.sensor`), atomic writes
(:mod:`.fileio`) and the output-ownership policy (:mod:`.outputs`: what the package may
overwrite, interrupted writes).

Floor: next to the ground floor (``errors``, ``constants``, ``limits``); imports no solver.
"""
