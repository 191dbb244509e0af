"""Generated-C simulation of the closed loop: CasADi codegen, gcc, cache, native CVODE, CVODES/IDAS/fixed step.

Stages (each a function in :mod:`generated.api`): load scenario -> synthesize ->
build (symbolic closed loop, C code generation, compile, cached under
``<build cache>/<sha256>/``, the user cache folder or ``$HITL_BUILD_DIR``) -> simulate
-> trajectory as a pandas DataFrame.
``python -m generated sim SCENARIO`` (``make sim``) runs them all and writes
``out/<name>/trajectory.csv`` and ``meta.json``.
"""

from generated.codegen import CodegenSettings, Library, build_library
from generated.integrate import IntegratorSettings, Trajectory, integrate

__all__ = [
    "CodegenSettings",
    "IntegratorSettings",
    "Library",
    "Trajectory",
    "build_library",
    "integrate",
]
