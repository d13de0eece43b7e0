"""Neural and grey-box models of EAP actuators, datasets, training and the ``eap`` command line."""


def load(path):
    """Load a trained network saved as a bundle (``eap train-compare`` writes them in ``RUN/models/``).

    Loading never runs code from the bundle: the card is JSON, the weights are read with
    ``torch.load(..., weights_only=True)``, and every size the card declares is checked before
    the weights are read.

    Parameters
    ----------
    path : str or path
        The bundle folder (``card.json`` and ``weights.pt``).

    Returns
    -------
    Bundle
        The network, ready to :meth:`~nnmodel.bundle.Bundle.predict`.

    Raises
    ------
    InputError
        A missing folder or file, a malformed card, weights that do not match it.

    Examples
    --------
    >>> import numpy as np, nnmodel
    >>> model = nnmodel.load("runs/train/models/ff")     # saved by eap train-compare ... --out runs/train
    >>> model.fs, model.rh_range                         # Hz, and the RH range seen in training [%]
    (50.0, (40.0, 80.0))
    >>> y = model.predict(np.zeros(200), rh=60.0, fs=50.0)   # tip deflection [m], free run from rest
    >>> y.shape
    (200,)
    """
    from .bundle import load as _load

    return _load(path)


def check_model(cls, params=None):
    """Run the network contract on a network class (a subclass of ``NeuralModel``).

    The checks: hyper-parameter conventions, fit, free run, one- and k-step prediction without
    look-ahead, NaN refused, bundle round trip, chunked free run, same seed → same model.  Each
    trains the network briefly on small synthetic records (its ``CHECK_PARAMS``).

    Parameters
    ----------
    cls : type
        The network class.
    params : dict, optional
        Hyper-parameters that override its ``CHECK_PARAMS``.

    Returns
    -------
    list of str
        The names of the checks passed.

    Raises
    ------
    ContractError
        At the first check that fails, naming it and what was found.

    Examples
    --------
    >>> import nnmodel
    >>> from nnmodel.models import MODELS
    >>> nnmodel.check_model(MODELS["ff"])
    ['check_class', 'check_params', 'check_fit_predict', 'check_inputs_refused', 'check_bundle', 'check_chunks', 'check_seeded']
    """
    from .models.check import check_model as _check

    return _check(cls, params)


def __getattr__(name):
    if name == "__version__":      # the package's one version (physics/_version.py), read on demand
        from physics._version import __version__
        return __version__
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = ["load", "check_model"]
