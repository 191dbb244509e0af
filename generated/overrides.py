"""``--set`` overrides and automatic run names: they live in :mod:`core.overrides`.

Kept so that ``from generated.overrides import ...`` goes on working; the code moved to
``core`` because every stage's command line (``synthesis`` too) takes ``--set``.
"""

from __future__ import annotations

from core.overrides import (
    MAX_SET_DEPTH,
    MAX_SET_INT,
    MAX_VARIANT_CHARS,
    add_scenario_knobs,
    load,
    parse_override,
    scenario_knobs,
    set_path,
)

__all__ = [
    "MAX_SET_DEPTH",
    "MAX_SET_INT",
    "MAX_VARIANT_CHARS",
    "add_scenario_knobs",
    "load",
    "parse_override",
    "scenario_knobs",
    "set_path",
]
