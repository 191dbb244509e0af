"""``python -m design run|demo SCENARIO`` (``make design``, ``make demo``)."""

from core.errors import run_cli
from design.cli import main

if __name__ == "__main__":
    raise SystemExit(run_cli(main))
