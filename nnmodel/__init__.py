"""Neural and grey-box models of EAP actuators, datasets, training and the ``eap`` command line."""


def load(path):
    """Load a saved model bundle (folder with ``card.json`` and weights): returns a
    :class:`nnmodel.bundle.Bundle` with ``.predict(voltage, rh=..., fs=..., steps_ahead=None,
    resample=False)``.  Imported lazily so that ``import nnmodel`` stays light."""
    from .bundle import load as _load

    return _load(path)


def check_model(cls, params=None):
    """Check a network class against the model contract (:mod:`nnmodel.models.check`):
    returns the checks passed, raises ``ContractError`` naming the first that fails."""
    from .models.check import check_model as _check

    return _check(cls, params)


def __getattr__(name):
    if name == "__version__":      # the package's one version (physics/_version.py), read on demand
        from physics._version import __version__
        return __version__
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = ["load", "check_model"]
