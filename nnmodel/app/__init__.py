"""The application: the ``eap`` command line (:mod:`.cli`), one module per command
(:mod:`.commands`) and the page of ``eap run`` (:mod:`.story`).  The library (``physics``,
the rest of ``nnmodel``) never imports it; commands map flags to library calls.
"""
