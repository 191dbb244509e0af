"""A build cache entry does not depend on the checkout or environment that built it.

- a freshly built native kernel library (generated/agent_kernels.py) records no
  RPATH/RUNPATH (its SUNDIALS libraries are named by soname only; ``readelf -d``);
- an entry built against SUNDIALS libraries in a fake checkout's ``.venv`` (copies of
  scikit-sundae's), whose folder is then deleted, runs from another process with this
  environment's libraries (preloaded before the entry is loaded);
- an entry that checks out (key, SHA-256) but cannot be loaded here, a native library
  whose NEEDED library is missing or bytes that are no shared library, is rebuilt with
  one line on stderr, never a traceback; a rebuilt entry runs;
- the per-agent kernel libraries built from one checkout of the packages, that checkout
  then deleted, are cache hits from another and give the same bits.

The native libraries are the per-agent kernels of the two-follower test scenario
(tests/helpers.py SMALL), compiled with -O0 into temporary build roots (about a second
and a half per build); a run of 0.1 s on a rebuilt or reused entry gives the bits of
the same run on the first build (the same compiled code).
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

from core.build_cache import LIBRARY_NAME, MANIFEST_NAME
from generated import native
from generated.codegen import Library, build_library
from generated.compiler import Toolchain
from generated.schedule import output_grid
from generated.values import CodegenSettings, IntegratorSettings

PY = sys.executable
ROOT = Path(__file__).resolve().parent.parent
LINE = re.compile(r"cache entry [0-9a-f]{12}: cannot be loaded here \(.+\); rebuilding")

#: builds (argv[2] == "build", against the libraries in argv[4]) or runs (argv[2] ==
#: "run", this environment's toolchain) the kernels of the scenario argv[3] in the build
#: root argv[1]; prints the library's path, whether it was a cache hit and x(0.1)
SCRIPT = """
import dataclasses, json, sys
from pathlib import Path
from generated import agents, native
from generated.api import load, scenario_gains
from generated.schedule import output_grid
from generated.values import CodegenSettings, IntegratorSettings

root, what, scenario = sys.argv[1:4]
if what == "build":
    libs = tuple(sorted(Path(sys.argv[4]).iterdir()))
    real = native.toolchain

    def fake():
        tc = real()
        return dataclasses.replace(tc, libraries=tuple(
            next(p for p in libs if p.name == lib.name) for lib in tc.libraries))

    native.toolchain = fake
sc = load(scenario)
gains = scenario_gains(sc, "portable")
cg = CodegenSettings(optimization="-O0", kernel_optimization="-O0", build_root=root)
(lib,), model = agents.build_models(sc, gains, cg)
tr = agents.run([lib.path], agents.problem(sc, gains, model), agents.initial_state(sc),
                output_grid(0.1, 0.01), IntegratorSettings(method="native"))
print(json.dumps({"path": str(lib.path), "hit": lib.cache_hit, "x": tr.x[-1].tolist(),
                  "complete": tr.complete}))
"""


@pytest.fixture
def small(tmp_path: Path) -> Path:
    from helpers import SMALL

    path = tmp_path / "small.toml"
    path.write_text(SMALL)
    return path


def kernels(scenario: Path, root: Path) -> tuple[Library, tuple]:
    """The kernel library of ``scenario`` in the build root ``root`` (the process's memo
    of built kernels bypassed: the cache entry is checked as a new process would)."""
    from generated import agent_kernels, agents, api

    agent_kernels._BUILT.clear()
    sc = api.load(scenario)
    gains = api.scenario_gains(sc, "portable")
    cg = CodegenSettings(optimization="-O0", kernel_optimization="-O0", build_root=str(root))
    (lib,), model = agents.build_models(sc, gains, cg)
    return lib, (agents.problem(sc, gains, model), agents.initial_state(sc))


def run_kernels(lib: Library, data: tuple) -> np.ndarray:
    """x(0.1) of a run on ``lib``."""
    from generated import agents

    prob, x0 = data
    tr = agents.run([lib.path], prob, x0, output_grid(0.1, 0.01), IntegratorSettings())
    assert tr.complete
    return tr.x[-1]


def script(*args: str) -> dict:
    r = subprocess.run(
        [PY, "-c", SCRIPT, *args], cwd=ROOT, capture_output=True, text=True, timeout=300
    )
    assert r.returncode == 0 and "Traceback" not in r.stderr, r.stderr
    return json.loads(r.stdout.splitlines()[-1])


def run_paths(library: Path) -> list[str]:
    """The RPATH and RUNPATH entries of a shared library (``readelf -d``)."""
    readelf = shutil.which("readelf")
    if readelf is None:
        pytest.skip("readelf (binutils) is not installed")
    out = subprocess.run([readelf, "-d", str(library)], capture_output=True, text=True).stdout
    return [
        p
        for m in re.finditer(r"\((?:RPATH|RUNPATH)\)\s+Library r(?:un)?path: \[(.*)\]", out)
        for p in m.group(1).split(":")
    ]


def rewrite_library(folder: Path, data: bytes) -> None:
    """``model.so`` replaced by ``data`` and the manifest's SHA-256 made to match."""
    import hashlib

    (folder / LIBRARY_NAME).write_bytes(data)
    info = json.loads((folder / MANIFEST_NAME).read_text())
    info["library_sha256"] = hashlib.sha256(data).hexdigest()
    (folder / MANIFEST_NAME).write_text(json.dumps(info))


def test_native_library_has_no_rpath_into_an_environment(tmp_path, small):
    lib, _ = kernels(small, tmp_path / "build")
    assert not lib.cache_hit
    paths = run_paths(lib.path)
    assert not [p for p in paths if p.startswith("/")], paths
    libdir = str(native.toolchain().libraries[0].parent)
    assert libdir not in lib.path.read_bytes().decode("latin-1")
    manifest = (lib.folder / MANIFEST_NAME).read_text()
    assert str(ROOT) not in manifest and sys.prefix not in manifest


def test_entry_built_in_a_deleted_checkout_runs_from_another(tmp_path, small):
    checkout = tmp_path / "old-checkout"
    libdir = checkout / ".venv" / "lib" / "site-packages" / "scikit_sundae.libs"
    libdir.mkdir(parents=True)
    real = native.toolchain().libraries[0].parent
    for p in real.iterdir():
        shutil.copy2(p, libdir / p.name)
    root = str(tmp_path / "build")
    built = script(root, "build", str(small), str(libdir))
    assert not built["hit"] and built["complete"]
    assert not [p for p in run_paths(Path(built["path"])) if p.startswith(str(checkout))]
    shutil.rmtree(checkout)
    ran = script(root, "run", str(small))
    assert ran["hit"] and ran["path"] == built["path"]  # same key: the entry is used
    assert ran["complete"] and ran["x"] == built["x"]  # the same code: the same bits


def test_native_entry_whose_needed_library_is_missing_is_rebuilt(tmp_path, capsys, small):
    first, data = kernels(small, tmp_path / "build")
    x = run_kernels(first, data)
    # a library that needs libgone.so, which is removed once it is linked
    (tmp_path / "gone.c").write_text("int gone(void) { return 1; }\n")
    (tmp_path / "use.c").write_text("int gone(void);\nint use(void) { return gone(); }\n")
    gcc = ["gcc", "-shared", "-fPIC"]
    subprocess.run([*gcc, str(tmp_path / "gone.c"), "-o", str(tmp_path / "libgone.so")], check=True)
    bad = tmp_path / "use.so"
    subprocess.run(
        [*gcc, str(tmp_path / "use.c"), "-o", str(bad), f"-L{tmp_path}", "-lgone"], check=True
    )
    (tmp_path / "libgone.so").unlink()
    rewrite_library(first.folder, bad.read_bytes())
    capsys.readouterr()
    again, data = kernels(small, tmp_path / "build")
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and LINE.fullmatch(err[0]) and "libgone.so" in err[0], err
    assert err[0].startswith(f"cache entry {first.key[:12]}:")
    assert not again.cache_hit and again.path == first.path
    assert np.array_equal(run_kernels(again, data), x)
    assert kernels(small, tmp_path / "build")[0].cache_hit  # the rebuilt entry loads


def test_casadi_entry_that_is_no_shared_library_is_rebuilt(tmp_path, capsys):
    x = ca.SX.sym("x", 2)
    f = ca.Function("sq", [x], [x * x])
    cg = CodegenSettings(optimization="-O0", build_root=str(tmp_path))
    first = build_library([f], cg)
    rewrite_library(first.folder, b"\x7fELF but not a shared library" * 64)
    capsys.readouterr()
    again = build_library([f], cg, toolchain=Toolchain())
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and LINE.fullmatch(err[0]), err
    assert not again.cache_hit
    np.testing.assert_allclose(np.array(again.function("sq")([2.0, 3.0])).ravel(), [4.0, 9.0])


#: builds (or reuses) the per-agent kernels of SMALL in the build root argv[1] and runs
#: 0.1 s on them, from whichever checkout is on PYTHONPATH; prints the libraries' paths,
#: whether they were cache hits, and x(0.1)
AGENTS_SCRIPT = """
import json, sys
from pathlib import Path
from core.scenario import load_scenario
from generated import agents
from generated.api import ensure_gains
from generated.schedule import output_grid
from generated.values import CodegenSettings, IntegratorSettings

root, scenario, out = sys.argv[1:4]
sc = load_scenario(scenario)
gains, _ = ensure_gains(sc, Path(out))
libs, model = agents.build_models(sc, gains, CodegenSettings(optimization="-O0", build_root=root))
t_out = output_grid(0.1, 0.01)
tr = agents.run([lib.path for lib in libs], agents.problem(sc, gains, model),
                agents.initial_state(sc), t_out, IntegratorSettings(method="native"),
                breakpoints=[b for b in sc.breakpoints() if b < 0.1])
print(json.dumps({"paths": [str(l.path) for l in libs], "hits": [l.cache_hit for l in libs],
                  "complete": tr.complete, "x": tr.x[-1].tolist()}))
"""


def _checkout(where: Path) -> Path:
    """A copy of the packages the agents path imports: a checkout of its own."""
    for pkg in ("core", "synthesis", "symbolic", "generated"):
        shutil.copytree(ROOT / pkg, where / pkg, ignore=shutil.ignore_patterns("__pycache__"))
    return where


def _agents_run(checkout: Path, root: Path, scenario: Path, out: Path) -> dict:
    r = subprocess.run(
        [PY, "-c", AGENTS_SCRIPT, str(root), str(scenario), str(out)],
        cwd=checkout,
        env={**os.environ, "PYTHONPATH": str(checkout)},
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert r.returncode == 0 and "Traceback" not in r.stderr, r.stderr
    return json.loads(r.stdout.splitlines()[-1])


@pytest.mark.slow
def test_agent_kernels_built_in_a_deleted_checkout_run_from_another(tmp_path):
    from helpers import SMALL

    scenario = tmp_path / "small.toml"
    scenario.write_text(SMALL)
    root = tmp_path / "build"
    first = _checkout(tmp_path / "checkout-a")
    built = _agents_run(first, root, scenario, tmp_path / "out-a")
    assert built["complete"] and not any(built["hits"])
    for path in map(Path, built["paths"]):
        assert not [p for p in run_paths(path) if p.startswith("/")]
        assert str(first) not in path.read_bytes().decode("latin-1")
        assert str(first) not in (path.parent / MANIFEST_NAME).read_text()
    shutil.rmtree(first)
    ran = _agents_run(_checkout(tmp_path / "checkout-b"), root, scenario, tmp_path / "out-b")
    assert all(ran["hits"]) and ran["paths"] == built["paths"]  # same keys: entries used
    assert ran["x"] == built["x"]  # the same compiled kernels: the same bits
