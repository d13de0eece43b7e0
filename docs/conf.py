"""Sphinx configuration of the eap-model documentation (``python docs/build.py`` builds it)."""
import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parent
sys.path.insert(0, str(DOCS.parent))          # document the checkout's code
sys.path.insert(0, str(DOCS / "_ext"))

from physics import __version__  # noqa: E402

project = "eap-model"
author = "eap-model developers"
copyright = "eap-model developers"
version = release = __version__

extensions = ["myst_parser", "sphinx.ext.autodoc", "sphinx.ext.napoleon", "eap_docs"]
source_suffix = {".md": "markdown"}
exclude_patterns = ["_build", "**/__pycache__"]
root_doc = "index"

myst_enable_extensions = ["deflist", "colon_fence"]
myst_heading_anchors = 3

# numpydoc docstrings, read by napoleon
napoleon_google_docstring = False
napoleon_numpy_docstring = True
napoleon_use_rtype = False
napoleon_preprocess_types = True       # {"cubic", "linear"} read as a set of literal values
napoleon_type_aliases = {          # short type names in docstrings -> the documented objects
    "Device": "~physics.Device", "FrequencyResponse": "~physics.FrequencyResponse",
    "SimulationResult": "~physics.SimulationResult", "InputError": "~physics.InputError",
    "ModelError": "~physics.ModelError", "ContractReport": "~physics.ContractReport",
    "Signal": "~physics.signals.Signal", "Bundle": "~nnmodel.bundle.Bundle",
}
napoleon_use_ivar = True              # Attributes sections as fields (autodoc lists no attribute twice)
autodoc_typehints = "none"            # types are in the numpydoc Parameters sections
autodoc_member_order = "bysource"
autodoc_default_options = {"undoc-members": False}

# Strict: python docs/build.py runs with -W -n (every warning and every unresolved reference fails).
# References into other projects' documentation are not resolved (no intersphinx: nothing is
# downloaded at build time); names from the standard library, numpy and torch are accepted as text.
nitpick_ignore_regex = [
    (r"py:.*", r"(np|numpy|torch|pathlib|typing|collections|dataclasses|os|argparse|pd|pandas)\..*"),
    (r"py:class", r"(Path|PathLike|ndarray|Callable|Mapping|Sequence|Iterable|Any|optional|array_like|"
                  r"array-like|float|int|str|bool|dict|list|tuple|None|type|object|callable|default .*|path|"
                  r"mapping|complex|time series)"),
    # classes named in docstrings whose use is told in the how-to guides, not in the API pages
    (r"py:(class|exc)", r"(NeuralModel|ContractError|ParamSpec)"),
]

smartquotes = False                   # "--out" stays two hyphens, quotes stay straight
html_theme = "furo"
html_title = f"eap-model {release}"
html_static_path = []
html_show_sourcelink = False
