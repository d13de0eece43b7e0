"""Exception types shared by the whole package.

Every error caused by what a user supplied (a device file, a measurement, an option)
is an :class:`InputError`: its message names the file, key or column and says what
was expected.  The command line prints such messages without a traceback.
"""


class InputError(ValueError):
    """Bad user input: a device file, a measurement file, a parameter or an option."""


class ModelError(RuntimeError):
    """A model cannot be built or solved with the given parameters (for example a
    realisation that cannot meet its accuracy target)."""


class InputNotice(UserWarning):
    """Something in the user's input was read in a way worth saying aloud (a unit taken from
    a column header, an output that is not a length); the command line prints each as one
    line ``eap CMD: note: …``."""
