"""Resuming a study: which samples a rerun runs again.

A row is final when its ``status`` is ``ok`` or ``refused: ...`` (the loader's refusal of
the drawn values is the same on every rerun); a ``failed: ...`` row (an exception, a
worker that died) is run again, and its new row replaces the old one.
"""

from __future__ import annotations

from typing import Any

import pandas as pd


def pending_ids(wanted: list[int], done: pd.DataFrame) -> tuple[list[int], int]:
    """The ids of ``wanted`` without a final row, and how many of them have a row (retries).

    Parameters
    ----------
    wanted : list of int
        The sample ids asked for, sorted.
    done : DataFrame
        The committed results (:func:`sweep.results.read_results`).

    Returns
    -------
    tuple
        The ids to run, in the order of ``wanted``, and the number of them retried.
    """
    final = final_ids(done)
    todo = [k for k in wanted if k not in final]
    return todo, len(set(todo) & set(int(x) for x in done["id"]))


def is_failed(status: Any) -> bool:
    """Whether a row's ``status`` is ``failed: ...`` (a fault of the run, retried by a rerun).

    Parameters
    ----------
    status : Any
        The row's ``status`` (``ok``, ``refused: ...``, ``failed: ...``).
    """
    return str(status).startswith("failed")


def final_ids(table: pd.DataFrame) -> set[int]:
    """Ids whose row is final: ``ok`` or ``refused`` (a rerun retries the ``failed`` ones).

    Parameters
    ----------
    table : DataFrame
        The committed results.
    """
    return {int(k) for k, s in zip(table["id"], table["status"], strict=True) if not is_failed(s)}


def faults_line(table: pd.DataFrame, study: str) -> str | None:
    """One line naming how many samples failed and the first reason; None when none did.

    Parameters
    ----------
    table : DataFrame
        The results.
    study : str
        The study file, for the rerun command.
    """
    failed = table[[is_failed(s) for s in table["status"]]].sort_values("id")
    if not len(failed):
        return None
    first = str(failed["status"].iloc[0]).removeprefix("failed").lstrip(": ")
    return (
        f"study faults: {len(failed)} of {len(table)} samples failed; first (id "
        f"{int(failed['id'].iloc[0])}): {first}; rerun `make sweep SWEEP={study}` retries them"
    )
