"""Synthetic test beds and the diagnosis demo, outside the library's core: records from a
known truth with one hidden effect (:mod:`.cases`) and the demo that diagnoses them
(:mod:`.demo`).  Used by ``eap demo``, the tests and the benches; the core never imports them.
"""
