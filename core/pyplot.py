"""matplotlib's pyplot on the file-only Agg backend: every figure of the toolkit is a file.

Imported lazily by the figure writers (a run that draws nothing never imports
matplotlib); selecting Agg before pyplot's first import means no window and no display
are ever needed, on a laptop or a headless CI machine alike.
"""

from __future__ import annotations

from types import ModuleType


def pyplot() -> ModuleType:
    """``matplotlib.pyplot`` with the Agg backend selected (files only, never a window).

    Returns
    -------
    module
        ``matplotlib.pyplot``.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt
