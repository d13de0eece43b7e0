"""A new network touches no file of the package: one module (here, this test) and its recipe.

The throwaway network below is written from scratch, not from a built-in: a one-pole
recurrent filter of the input channels with a tanh read-out.  It passes the whole model
contract (``nnmodel.check_model``), its recipe is read from its own folder, and once
registered the package builds, trains and saves it like any other network."""
import shutil

import numpy as np
import torch
from torch import nn

import nnmodel
from nnmodel.bundle import save
from nnmodel.models import MODELS, register
from nnmodel.models.base import NeuralModel
from nnmodel.models.check import CHECKS, _records
from nnmodel.models.core import SequenceCore
from nnmodel.recipes import load_recipe, make_model, recipe_dir


class _PoleCore(SequenceCore):
    """x[t] = a x[t-1] + B c[t];  y[t] = w · tanh(x[t]) + d · c[t] (c: the input channels)."""

    n_init = 1

    def __init__(self, n_in: int, states: int):
        super().__init__()
        self.a = nn.Parameter(torch.full((states,), 0.9))
        self.b = nn.Linear(n_in, states)
        self.w = nn.Linear(states, 1)
        self.d = nn.Linear(n_in, 1, bias=False)

    def init_state(self, u_hist, y_hist, rh_hist):
        return torch.zeros(y_hist.shape[0], self.a.numel())

    def advance(self, state, u, rh):
        c = u[..., None] if u.dim() == 2 else u
        if rh is not None:
            c = torch.cat([c, rh[..., None] if rh.dim() == 2 else rh], -1)
        drive, out = self.b(c), []
        for t in range(c.shape[1]):
            state = torch.clamp(self.a, -0.999, 0.999) * state + drive[:, t]
            out.append(state)
        x = torch.stack(out, 1)
        return self.w(torch.tanh(x))[..., 0] + self.d(c)[..., 0], state

    def simulate(self, state, u, rh):
        return self.advance(state, u, rh)[0]


class PoleNet(NeuralModel):
    """The throwaway network: its own parameter (``states``), everything else shared."""

    kind = "polenet"
    CHECK_PARAMS = {"max_epochs": 1, "horizon": 20, "stride": 20}

    def __init__(self, states: int = 4, **settings):
        self._set_params_from(locals())

    def _build_core(self, features):
        return _PoleCore(1 + features.n_ref + features.n_mem + features.n_rh, self.states)


RECIPE = """model: polenet
description: one-pole recurrent filter bank with a tanh read-out (a test network)
hyper_parameters:
  states: 3
  max_epochs: 2
  horizon: 20
  stride: 20
  batch_size: 1
  progress_bar: false
"""


def test_a_new_network_is_one_module_plus_its_recipe(tmp_path):
    assert nnmodel.check_model(PoleNet) == [c.__name__ for c in CHECKS]     # before registering: nothing to edit
    for f in recipe_dir().glob("*.yaml"):     # the user's recipe folder: the shipped recipes plus theirs
        shutil.copy(f, tmp_path)
    (tmp_path / "polenet.yaml").write_text(RECIPE)
    register(PoleNet)
    try:
        assert load_recipe("polenet", directory=tmp_path)["hyper_parameters"]["states"] == 3
        model = make_model("polenet", {"seed": 1}, directory=tmp_path)
        recs = _records(300)
        model.fit(recs[:1], recs[1:])
        y = model.simulate(recs[0].u, 40.0)
        assert y.shape == recs[0].u.shape and np.all(np.isfinite(y))
        saved = nnmodel.load(save(model, tmp_path / "run" / "polenet"))
        assert np.allclose(saved.predict(recs[0].u, rh=40.0, fs=recs[0].fs), y, rtol=1e-6, atol=1e-12)
    finally:
        MODELS.pop(PoleNet.kind)


def test_an_installed_network_is_found_by_the_eap_command(tmp_path, monkeypatch, capsys):
    """A package declaring the network under the entry-point group ``eap.networks`` (its
    recipe beside its module) is trained by ``eap train-compare --models polenet`` and its
    bundle reloads, with no file of the package touched and nothing registered by hand."""
    import inspect
    import json

    from nnmodel.app.cli import main
    from nnmodel.dataset import generate
    site = tmp_path / "site"
    site.mkdir()
    (site / "eap_polenet.py").write_text(
        "import torch\nfrom torch import nn\nfrom nnmodel.models.base import NeuralModel\n"
        "from nnmodel.models.core import SequenceCore\n\n\n"
        + inspect.getsource(_PoleCore) + "\n\n" + inspect.getsource(PoleNet))
    (site / "polenet.yaml").write_text(RECIPE)
    dist = site / "eap_polenet-0.1.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: eap-polenet\nVersion: 0.1\n")
    (dist / "entry_points.txt").write_text("[eap.networks]\npolenet = eap_polenet:PoleNet\n")
    monkeypatch.syspath_prepend(str(site))
    ds = generate(tmp_path / "ds", dict(fs_Hz=100.0, f_max_Hz=20.0, duration_s=4.0, train_rh_pct=[40, 100],
                                        heldout_rh_pct=[70], excitations=["noise"], validation_per_rh=1,
                                        test_per_train_rh=1, test_per_heldout_rh=1), progress=False)
    assert "polenet" not in MODELS
    try:
        assert main(["train-compare", str(ds), "--models", "polenet", "--quiet", "--out", str(tmp_path / "run")]) == 0
        assert MODELS["polenet"].__module__ == "eap_polenet"      # the installed class, not this test's
        card = json.loads((tmp_path / "run" / "models" / "polenet" / "card.json").read_text())
        assert card["model"] == "polenet" and card["hyper_parameters"]["states"] == 3
        assert "polenet" in capsys.readouterr().out
    finally:
        MODELS.pop("polenet", None)
        import sys
        sys.modules.pop("eap_polenet", None)


def test_the_default_set_is_what_the_networks_declare():
    """No network kind is named by the core: the set trained when none are named is the networks'
    own ``IN_DEFAULT_SET``, a plug-in joins it by declaring it, and the command's help (written
    without importing torch) says the same set."""
    from nnmodel.app.commands.train_compare import DEFAULT_SET
    from nnmodel.models import default_kinds
    assert ", ".join(default_kinds()) == DEFAULT_SET
    assert "gru" not in default_kinds() and "hybrid" not in default_kinds()

    class Joins(PoleNet):
        kind = "joins"
        IN_DEFAULT_SET = True
    register(Joins)
    try:
        assert default_kinds()[-1] == "joins" and len(default_kinds()) == len(DEFAULT_SET.split(", ")) + 1
    finally:
        MODELS.pop("joins")
