"""The network contract over every entry of the model registry: a model is tested the moment
it is registered (nnmodel.check_model: hyper-parameter conventions, fit, free run, one-step
and k-step, NaN refused, bundle round trip, chunked free run, seeded), and the check
itself catches a model that breaks the contract."""
import numpy as np
import pytest

import nnmodel
from nnmodel.models import MODELS, register
from nnmodel.models.check import CHECKS, ContractError, model_checks
from nnmodel.models.ff import FFModel
from physics.errors import InputError


#: one shared fit per registered network, one test item per check of the contract
_CHECKS = {kind: dict(model_checks(MODELS[kind])) for kind in sorted(MODELS)}


@pytest.mark.parametrize("kind, check", [(k, c) for k, checks in _CHECKS.items() for c in checks])
def test_registered_model_honours_the_contract(kind, check):
    _CHECKS[kind][check]()


def test_check_model_runs_every_check_and_names_each_failure():
    assert nnmodel.check_model(MODELS["ff"]) == [c.__name__ for c in CHECKS]
    assert [name for name, _ in model_checks(FFModel)] == [c.__name__.removeprefix("check_") for c in CHECKS]


def test_training_settings_live_in_one_config():
    """No constructor repeats the shared settings (training, features, structures)."""
    import inspect

    from nnmodel.models.base import PARTS
    shared = {n for part in PARTS for n in part.names()}
    for kind, cls in MODELS.items():
        own = set(inspect.signature(cls.__init__).parameters) - {"self", "settings"}
        assert not own & shared, (kind, sorted(own & shared))


class _Repeats(FFModel):
    """Repeats a training setting in its constructor."""

    kind = "repeats"

    def __init__(self, na: int = 2, nb: int = 20, hidden: int = 32, layers: int = 2, activation: str = "tanh",
                 poly_degree: int = 1, feedthrough: bool = True, arx_init: bool = True, max_epochs: int = 3,
                 **settings):
        self._set_params_from(locals())


class _Unseeded(FFModel):
    """Initialises its bypass from an unseeded generator: two fits differ."""

    kind = "unseeded"

    def _initialise(self, core, train):
        import torch
        super()._initialise(core, train)
        with torch.no_grad():
            core.fmap.lin_x.bias.add_(float(np.random.default_rng().normal()))


class _Forgetful(FFModel):
    """Forgets the memory-filter range in its card: the loaded bundle predicts differently."""

    kind = "forgetful"

    def _card_extra(self):
        return {"memory_range_s": [1.0, 2.0]}


@pytest.mark.parametrize("cls, check", [(_Repeats, "class"), (_Unseeded, "seeded"), (_Forgetful, "bundle")])
def test_the_check_catches_a_model_that_breaks_the_contract(cls, check):
    params = {"memory_filters": 2} if cls is _Forgetful else None
    with pytest.raises(ContractError, match=f"^{check}:"):
        nnmodel.check_model(cls, params)
    assert cls.kind not in MODELS      # checking does not register


def test_register_refuses_a_repeated_setting_or_a_taken_kind():
    with pytest.raises(InputError, match="max_epochs"):
        register(_Repeats)

    class Twin(FFModel):
        kind = "narx"
    with pytest.raises(InputError, match="already registered"):
        register(Twin)
