"""Follower model library. Importing this package registers every shipped model.

Adding a model is one small file that calls :func:`register` with a
:class:`ModelSpec` (its Lagrangian), plus one import line below.
"""

from core.models import point_mass_2d, point_mass_3d, two_link  # noqa: F401  (registers)
from core.models.base import REGISTRY, ELModel, ModelSpec, register
from core.models.derive import build_model

__all__ = ["REGISTRY", "ELModel", "ModelSpec", "build_model", "register"]
