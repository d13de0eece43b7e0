"""Sub-commands of the ``eap`` command line (one module per command, found automatically)."""
