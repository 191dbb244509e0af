"""Generated-C simulation of the closed loop: CasADi codegen, gcc, cache, integrators.

``python -m generated sim SCENARIO`` (``make sim``) writes ``out/<name>/trajectory.csv``
and ``meta.json``; the stages are functions of :mod:`generated.api`.
"""
