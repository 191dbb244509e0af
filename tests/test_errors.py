"""The shared error family and strict-mode reading used by every command."""

import pytest

from core.errors import ScenarioError, UsageError, strict_mode


@pytest.mark.parametrize("value", ["1", "true", "YES", "on"])
def test_strict_on(monkeypatch, value):
    monkeypatch.setenv("STRICT", value)
    assert strict_mode(False) is True


@pytest.mark.parametrize("value", ["", "0", "false", "no", "OFF"])
def test_strict_off_unless_flag(monkeypatch, value):
    monkeypatch.setenv("STRICT", value)
    assert strict_mode(False) is False
    assert strict_mode(True) is True


def test_strict_rejects_unknown_value(monkeypatch):
    monkeypatch.setenv("STRICT", "maybe")
    with pytest.raises(UsageError, match="STRICT"):
        strict_mode(False)


def test_messages_are_one_line():
    err = ScenarioError("f.toml", "leader.A0", "has\nshape 3x3", "shape 2x2")
    assert "\n" not in str(err)
    assert str(err).startswith("f.toml: leader.A0:")


def test_atomic_write_has_ordinary_permissions(tmp_path):
    import os
    import stat

    from core.artifacts import atomic_write_text

    mask = os.umask(0o022)
    os.umask(mask)
    path = atomic_write_text(tmp_path / "x.csv", "a,b\n")
    assert path.read_text() == "a,b\n"
    assert stat.S_IMODE(path.stat().st_mode) == 0o666 & ~mask
    assert [p.name for p in tmp_path.iterdir()] == ["x.csv"]  # no temporary left behind
