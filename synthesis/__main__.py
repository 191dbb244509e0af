"""``python -m synthesis synth SCENARIO`` and ``python -m synthesis certify GAINS``."""

from __future__ import annotations

import sys

from core.errors import run_cli
from synthesis.cli import main

if __name__ == "__main__":
    sys.exit(run_cli(main))
