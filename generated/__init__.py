"""Generated-C simulation of the closed loop: CasADi codegen, gcc, cache, native CVODE, CVODES/IDAS/fixed step.

Stages (each a function in :mod:`generated.api`): load scenario -> synthesize ->
build (symbolic closed loop, C code generation, compile, cached under
``<build cache>/<sha256>/``, the user cache folder or ``$HITL_BUILD_DIR``) -> simulate
-> trajectory as a pandas DataFrame.
``python -m generated sim SCENARIO`` (``make sim``) runs them all and writes
``out/<name>/trajectory.csv`` and ``meta.json``. The values the modules pass each
other are in :mod:`generated.values`, the package's import leaf.
"""
