"""The package's version, its single source (``pyproject.toml`` reads it; ``eap --version`` prints it)."""
__version__ = "0.3.0"
