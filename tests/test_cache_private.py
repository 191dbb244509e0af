"""The build cache is its user's alone: created private, and nothing others could write is loaded.

A planted library (its constructor writes a marker file when it is loaded) with a valid
manifest is put into an entry that someone else could have written: a world-writable
entry folder, a world-writable cache root, an entry owned by another user (as root, a
``chown`` to ``nobody``). It must never be loaded: the marker never appears and the
build is refused in one line. The same planted entry in a private folder is loaded,
which shows the marker would tell.
"""

from __future__ import annotations

import errno
import hashlib
import json
import os
import stat
import subprocess
from pathlib import Path

import casadi as ca
import pytest

from core.build_cache import LIBRARY_NAME, MANIFEST_NAME
from core.errors import BuildError, run_cli
from core.models import cache
from generated import codegen
from generated.codegen import CodegenSettings, build_library
from generated.loaded import verified_bytes

PLANT = r"""
#include <stdio.h>
__attribute__((constructor)) static void planted(void) {
    FILE *f = fopen("%s", "w");
    if (f) { fputs("loaded", f); fclose(f); }
}
"""


def tiny() -> ca.Function:
    x = ca.SX.sym("x")
    return ca.Function("tiny_private", [x], [2 * x])


def _built(root: Path) -> codegen.Library:
    return build_library([tiny()], CodegenSettings(build_root=str(root), optimization="-O0"))


def _plant(lib: codegen.Library, tmp_path: Path) -> Path:
    """Replace the entry's library by one whose constructor writes a marker; a valid manifest."""
    marker = tmp_path / "marker"
    src = tmp_path / "plant.c"
    src.write_text(PLANT % marker)
    so = lib.folder / LIBRARY_NAME
    subprocess.run(["gcc", "-shared", "-fPIC", "-o", str(so), str(src)], check=True)
    manifest = lib.folder / MANIFEST_NAME
    info = json.loads(manifest.read_text())
    info["library_sha256"] = hashlib.sha256(so.read_bytes()).hexdigest()
    manifest.write_text(json.dumps(info))
    os.chmod(so, 0o700)
    os.chmod(manifest, 0o600)
    return marker


def _refused(root: Path, capsys) -> str:
    def main(argv: list[str]) -> int:
        _built(root)
        return 0

    assert run_cli(main, []) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "Traceback" not in err
    return err


def test_a_private_planted_entry_is_loaded_so_the_marker_tells(tmp_path):
    """The control: in a private cache the planted library's constructor runs."""
    lib = _built(tmp_path / "cache")
    marker = _plant(lib, tmp_path)
    _built(tmp_path / "cache")
    assert marker.read_text() == "loaded"


def test_world_writable_entry_is_never_loaded(tmp_path, capsys):
    root = tmp_path / "cache"
    lib = _built(root)
    marker = _plant(lib, tmp_path)
    os.chmod(lib.folder, 0o777)
    err = _refused(root, capsys)
    assert f"{lib.folder} is writable by its group and others (mode 0777)" in err
    assert f"rm -rf {lib.folder}" in err
    with pytest.raises(BuildError, match="writable by"):
        verified_bytes(lib)  # the loader's own check, for a build kept in memory
    assert not marker.exists()


def test_group_writable_library_file_is_never_loaded(tmp_path, capsys):
    root = tmp_path / "cache"
    lib = _built(root)
    marker = _plant(lib, tmp_path)
    os.chmod(lib.folder / LIBRARY_NAME, 0o770)
    err = _refused(root, capsys)
    assert f"{lib.folder / LIBRARY_NAME} is writable by its group" in err
    assert not marker.exists()


def test_world_writable_cache_root_is_refused(tmp_path, capsys, monkeypatch):
    root = tmp_path / "shared"
    lib = _built(root)
    marker = _plant(lib, tmp_path)
    os.chmod(root, 0o1777)
    monkeypatch.setenv("HITL_BUILD_DIR", str(root))
    err = _refused(root, capsys)
    assert err.startswith(f"error: build cache refused: {root} is writable by its group")
    assert "HITL_BUILD_DIR" in err and "chmod 700" in err
    assert not marker.exists()
    with pytest.raises(BuildError, match="build cache refused"):  # the start-up caches too
        cache.read_entry("gains", "0" * 64)


@pytest.mark.skipif(os.getuid() != 0, reason="chown to another user needs root")
def test_entry_owned_by_another_user_is_never_loaded(tmp_path, capsys):
    import pwd

    nobody = pwd.getpwnam("nobody").pw_uid
    root = tmp_path / "cache"
    lib = _built(root)
    marker = _plant(lib, tmp_path)
    os.chown(lib.folder, nobody, -1)  # mode 0700: writable by its owner only, who is not us
    err = _refused(root, capsys)
    assert f"{lib.folder} is owned by nobody (uid {nobody}), not by you" in err
    assert not marker.exists()


def test_cache_is_private_whatever_the_umask(tmp_path):
    root = tmp_path / "a" / "b" / "cache"
    old = os.umask(0)
    try:
        lib = _built(root)
        cache.write_entry("gains", "1" * 64, {"x": 1}, root)
    finally:
        os.umask(old)
    for p in (tmp_path / "a", tmp_path / "a" / "b", root, lib.folder, root / "gains"):
        assert stat.S_IMODE(p.stat().st_mode) == 0o700, p
    assert stat.S_IMODE((lib.folder / LIBRARY_NAME).stat().st_mode) == 0o700
    for f in (lib.folder / MANIFEST_NAME, lib.source, root / "gains" / f"{'1' * 64}.json"):
        assert stat.S_IMODE(f.stat().st_mode) == 0o600, f
    assert cache.read_entry("gains", "1" * 64, root) == {"x": 1}


def test_deeply_nested_manifest_is_a_corrupt_entry_rebuilt(tmp_path, capsys):
    root = tmp_path / "cache"
    lib = _built(root)
    (lib.folder / MANIFEST_NAME).write_text("[" * 200_000 + "]" * 200_000)
    again = _built(root)  # no RecursionError: reported, rebuilt
    err = capsys.readouterr().err
    assert "manifest nests 200000 levels deep" in err and "rebuilding" in err
    assert not again.cache_hit and codegen.entry_problem(again.folder, again.key) is None
    assert _built(root).cache_hit


def test_deeply_nested_startup_cache_entry_reads_as_missing(tmp_path):
    cache.write_entry("gains", "2" * 64, {"x": 1}, tmp_path)
    cache.entry_path("gains", "2" * 64, tmp_path).write_text("[" * 200_000)
    assert cache.read_entry("gains", "2" * 64, tmp_path) is None


def test_full_cache_disk_names_the_cache(tmp_path, capsys, monkeypatch):
    root = tmp_path / "cache"

    def full(*a, **k):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))  # as a write() raises it

    monkeypatch.setattr(codegen, "compile_source", full)
    err = _refused(root, capsys)
    assert f"cannot write to {root}: No space left on device" in err
    assert f"free space on the disk of the build cache {root}" in err
    assert "HITL_BUILD_DIR" in err and "output" not in err and "--out" not in err
    assert [p.name for p in root.iterdir()] == []  # the temporary build folder is gone


def test_startup_cache_entry_others_may_write_is_refused(tmp_path):
    """Gains and model entries (core/models/cache.py) follow the libraries' rule."""
    path = cache.write_entry("models", "3" * 64, {"x": 1}, tmp_path)
    assert cache.read_entry("models", "3" * 64, tmp_path) == {"x": 1}
    os.chmod(path, 0o666)
    with pytest.raises(BuildError, match=f"{path} is writable by its group and others"):
        cache.read_entry("models", "3" * 64, tmp_path)
