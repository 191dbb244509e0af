"""A console record after a failed save: every logged row exactly once, each line whole.

The run's log spool gets a disk-full error half-way through an append (the bytes before
it are on file, as a real ``ENOSPC`` leaves them); the next save, with space again, must
hold exactly the rows logged, once each, every line with the header's field count, the
values the session logged; the failed save leaves no folder.
"""

from __future__ import annotations

import csv
import errno
import os
import tempfile
import time
from pathlib import Path

import numpy as np
import pytest
from console_fake import FakeLoop

import console.record as record
from console.record import LOG_NAME, Recorder
from console.session import Session


def _table() -> dict:
    """The fields a record's replay needs (not loaded back: FakeLoop)."""
    return {"name": "fake", "leader": {"u0": ["0"]}, "graph": {}, "followers": [{}, {}, {}]}


class FullOnce:
    """A file whose ``fail_at``-th write puts half its bytes on file, then fails ENOSPC."""

    def __init__(self, f, fail_at: int) -> None:
        self.f, self.calls, self.fail_at = f, 0, fail_at

    def write(self, data) -> int:
        self.calls += 1
        if self.calls == self.fail_at:
            data = bytes(data)
            self.f.write(data[: len(data) // 2])
            if hasattr(self.f, "flush"):
                self.f.flush()
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return self.f.write(data)

    def __getattr__(self, name):
        return getattr(self.f, name)


def _ticks(session: Session, n: int) -> None:
    for _ in range(n):
        time.sleep(0.02)
        session.tick()


def _rows(path: Path) -> list[list[str]]:
    with path.open(newline="") as fh:
        return list(csv.reader(fh))


@pytest.mark.parametrize("fail_at", [2, 3])  # the first save's append, or the second's
def test_a_failed_save_leaves_nothing_the_next_reuses(tmp_path, monkeypatch, fail_at):
    real = tempfile.TemporaryFile
    monkeypatch.setattr(
        record.tempfile, "TemporaryFile", lambda *a, **k: FullOnce(real(*a, **k), fail_at)
    )
    loop = FakeLoop()
    rec = Recorder(tmp_path, _table(), loop)
    session = Session(loop, recorder=rec)
    saved = []
    for _ in range(3):
        _ticks(session, 4)
        try:
            saved.append(rec(session.snapshot()))
        except OSError as exc:
            assert exc.errno == errno.ENOSPC
    assert len(saved) == 2  # one of the three failed
    last = saved[-1]
    rows = _rows(Path(last["folder"]) / LOG_NAME)
    header, body = rows[0], rows[1:]
    assert len(body) == last["rows"] == len(session.log_t)
    assert {len(r) for r in body} == {len(header)}
    t = [float(r[0]) for r in body]
    assert t == session.log_t  # every logged time once, in order
    X = loop.state_table(np.asarray(session.log_x))
    np.testing.assert_array_equal(np.array([[float(v) for v in r[1:]] for r in body]), X)
    folders = sorted(p for p in tmp_path.iterdir() if not p.name.startswith("."))
    assert [str(p) for p in folders] == sorted(r["folder"] for r in saved)  # none half-written
