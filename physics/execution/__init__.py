"""The execution layer behind sweeps and long runs: local or Dask parallelism
(:mod:`.parallel`), thread limits (:mod:`.threads`), memory estimates (:mod:`.memory`) and
progress bars (:mod:`.progress`).

Also how user code runs: plug-ins from entry points (:mod:`.plugins`) and effect files, contained
(:mod:`.usercode`: exit calls caught, time limits).

Floor: next to the ground floor; knows nothing of the physics it runs.
"""
