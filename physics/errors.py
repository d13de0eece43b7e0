"""Exception types shared by the whole package.

Every error caused by what a user supplied (a device file, a measurement, an option)
is an :class:`InputError`: its message names the file, key or column and says what
was expected.  The command line prints such messages without a traceback.

Errors name the caller's *arguments* (the keyword arguments of the Python API), never a
command-line flag: a message mentions an argument through :func:`arg`, e.g.
``InputError(f"no relative humidity; give it with {arg('rh')}")``.  ``str(error)`` spells
it as the Python argument (``rh``); a front end spells it its own way with
:meth:`InputError.render` (the ``eap`` command line prints its flag, ``--rh``).
"""
from __future__ import annotations

import re

_MARK = "\x1f"
_ARG = re.compile(_MARK + r"([A-Za-z_][A-Za-z0-9_]*)(?:\x1e([^\x1f]*))?" + _MARK)


def arg(name: str, python: str | None = None) -> str:
    """A reference to the argument ``name`` inside an :class:`InputError` message.

    ``name`` is the argument's key, which a front end maps to its own spelling (the command
    line: the flag whose destination is ``name``, e.g. ``fs_Hz`` → ``--fs-Hz``); ``python`` is
    how a Python caller reads it when that differs from ``name`` (e.g. the function to call)."""
    if not name.isidentifier():
        raise ValueError(f"arg: {name!r} is not an identifier")
    return f"{_MARK}{name}\x1e{python}{_MARK}" if python else f"{_MARK}{name}{_MARK}"


class InputError(ValueError):
    """Bad user input: a device file, a measurement file, a parameter or an option.

    A subclass of ``ValueError``.  The message names the file, key, column or argument and
    says what was expected; the ``eap`` command line prints it as one line, with the
    command-line flag in place of the Python argument.

    Attributes
    ----------
    params : tuple of str
        The arguments the message refers to, in order.

    Examples
    --------
    >>> import physics
    >>> try:
    ...     physics.load_device("no_such_device")
    ... except physics.InputError as exc:
    ...     print(exc)
    unknown device 'no_such_device': not a YAML file and not one of ip2c_pedot_water, ipmc_pt_eg
    """

    def __init__(self, message: str = "", *args):
        self.template = str(message)
        self.params = tuple(dict.fromkeys(m.group(1) for m in _ARG.finditer(self.template)))
        super().__init__(self.render(), *args)

    def render(self, spell=None) -> str:
        """The message with every argument spelled by ``spell(name)`` (a string, or None to
        keep the Python spelling); without ``spell``, as a Python caller reads it."""
        def sub(m):
            own = spell(m.group(1)) if spell else None
            return own if own is not None else (m.group(2) or m.group(1))
        return _ARG.sub(sub, self.template)

    def __reduce__(self):        # keep the argument references across processes (pickle)
        return type(self), (self.template,) + self.args[1:], self.__dict__


class ModelError(RuntimeError):
    """A model cannot be built or solved with the given parameters.

    A subclass of ``RuntimeError``: for example a simulation that is not finite, or that bends
    the tip beyond the strip's free length (an unstable effect or a parameter out of range).

    Examples
    --------
    A program that runs models on user input catches both kinds of error:

    >>> import physics
    >>> def gain_at_1hz(device):
    ...     try:
    ...         return physics.frequency_response(device, "none", [1.0]).magnitude[0]
    ...     except (physics.InputError, physics.ModelError) as exc:
    ...         return f"refused: {exc}"
    >>> gain_at_1hz("ipmc_pt_eg.yml")
    'refused: device file ipmc_pt_eg.yml does not exist'
    """


class InputNotice(UserWarning):
    """Something in the user's input was read in a way worth saying aloud (a unit taken from
    a column header, an output that is not a length); the command line prints each as one
    line ``eap CMD: note: …``."""
