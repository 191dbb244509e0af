"""Certified synthesis: assumptions, Lemma 3, LMIs (15)–(16), gains and their certificate.

The public names are imported on first use, so that ``synthesis.assumptions`` (graph and
leader checks, used by the symbolic layer) does not pull in cvxpy.
"""

from importlib import import_module

__all__ = ["Gains", "certify", "load_gains", "save_gains", "synthesize"]
_HOME = {
    "Gains": "synthesis.gains",
    "certify": "synthesis.certificate",
    "load_gains": "synthesis.gains",
    "save_gains": "synthesis.gains",
    "synthesize": "synthesis.api",
}


def __getattr__(name: str):
    if name in _HOME:
        return getattr(import_module(_HOME[name]), name)
    raise AttributeError(f"module 'synthesis' has no attribute {name!r}")
