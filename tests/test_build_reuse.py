"""Runs of one structure in one process share the loaded library, and nothing else changes.

- a later scenario of a structure gets the library loaded for the first (the same loaded
  Functions), and the trajectory the first run gave;
- a library rewritten in place after it was loaded (another structure's library of the
  same signature copied over it) is never called: the next build in that process
  rebuilds it and gives the trajectory of the undamaged library, and the process exits
  cleanly (in a subprocess, once per method family: CasADi's CVODES and the native driver);
- a library only touched (same bytes, new time stamps) is loaded again, not rebuilt;
- the outputs evaluated for all output times in one call equal the outputs Function
  (p filled in) called at each time separately;
- the schedule's targets equal those of a plain loop over the output times.

The scenario is the two-follower, 0.5 s one of test_sim_api (compiled with -O0 into a
temporary build root).
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from helpers import SMALL

from generated import api
from generated.built import Built
from generated.schedule import schedule, time_tolerance
from generated.values import CodegenSettings, Trajectory

PY = sys.executable
ROOT = Path(__file__).resolve().parent.parent

#: run in a fresh process: two runs of one scenario, another structure's library copied
#: over the first's in place, a third run; prints what it saw as JSON
SCRIPT = """
import json, sys
from pathlib import Path
import numpy as np
from generated import api
from generated.values import CodegenSettings

small, other, build_root, out, method = sys.argv[1:6]
cg = CodegenSettings(optimization="-O0", build_root=build_root)

def run(path):
    sc = api.load(path)
    gains, _ = api.ensure_gains(sc, Path(out))
    b = api.build(sc, gains, method, cg)
    tr = api.simulate(b, sc, api.integrator_settings(sc, method, cg))
    return b, api.trajectory_frame(b, sc, tr).to_numpy()

b1, f1 = run(small)
b2, f2 = run(small)
bo, fo = run(other)
b1.library.path.write_bytes(bo.library.path.read_bytes())  # same inode: mapped pages change
b3, f3 = run(small)
print(json.dumps({
    "same_loaded": b2.outputs_p is b1.outputs_p,
    "second_equal": bool(np.array_equal(f2, f1)),
    "other_differs": not np.array_equal(fo, f1),
    "rebuilt": not b3.library.cache_hit,
    "third_equal": bool(np.array_equal(f3, f1)),
}))
"""


@pytest.fixture(scope="module")
def env(tmp_path_factory):
    root = tmp_path_factory.mktemp("reuse")
    small = root / "small.toml"
    small.write_text(SMALL)
    other = root / "sin.toml"
    text = SMALL.replace('u0 = ["2*cos(t)"]', 'u0 = ["2*sin(t)"]').replace('"small"', '"sin"')
    assert text != SMALL  # another expression form: another structure, another library
    other.write_text(text)
    cg = CodegenSettings(optimization="-O0", build_root=str(root / "build"))
    return {"root": root, "small": small, "other": other, "cg": cg}


@pytest.mark.parametrize("method", ["cvodes", "native"])
def test_library_rewritten_in_place_is_rebuilt_and_the_process_exits_cleanly(env, method):
    argv = [str(env["small"]), str(env["other"]), env["cg"].build_root, str(env["root"] / "out")]
    r = subprocess.run(
        [PY, "-c", SCRIPT, *argv, method],
        capture_output=True,
        text=True,
        timeout=900,
        cwd=ROOT,
    )
    assert r.returncode == 0, r.stderr[-2000:]  # no crash, at the rebuild or at exit
    seen = json.loads(r.stdout.strip().splitlines()[-1])
    assert seen == {
        "same_loaded": True,
        "second_equal": True,
        "other_differs": True,
        "rebuilt": True,
        "third_equal": True,
    }
    assert "rebuilding" in r.stderr and "SHA-256" in r.stderr


def _run(env, path: Path) -> tuple[Built, pd.DataFrame, Trajectory]:
    sc = api.load(path)
    gains, _ = api.ensure_gains(sc, env["root"] / "out")
    b = api.build(sc, gains, None, env["cg"])
    tr = api.simulate(b, sc, api.integrator_settings(sc, None, env["cg"]))
    return b, api.trajectory_frame(b, sc, tr), tr


def test_touched_library_is_loaded_again_not_rebuilt(env):
    b1, f1, _ = _run(env, env["small"])
    st = os.stat(b1.library.path)
    os.utime(b1.library.path, ns=(st.st_atime_ns, st.st_mtime_ns + 1_000_000))
    b2, f2, _ = _run(env, env["small"])
    assert b2.library.cache_hit and b2.library.path == b1.library.path
    assert b2.outputs_p is not b1.outputs_p  # loaded again from the unchanged bytes
    pd.testing.assert_frame_equal(f2, f1, check_exact=True)


def test_outputs_at_all_times_equal_the_outputs_at_each_time(env):
    b, _, tr = _run(env, env["small"])
    outs = api.evaluate_outputs(b, tr)
    f = b.outputs  # p filled in: a second way to the same numbers
    for k in range(len(tr.t)):
        res = f(tr.t[k], tr.x[k])
        for j, nm in enumerate(f.name_out()):
            assert np.array_equal(outs[nm][k], np.array(res[j].full())), (nm, k)


def _loop_targets(t_out: np.ndarray, breaks: np.ndarray, tol: float) -> np.ndarray:
    """Per output time: the nearer of the breaks around it (the earlier on a tie), if within tol."""
    targets = t_out.copy()
    for k in range(1, t_out.size):
        near = [b for b in breaks if abs(b - t_out[k]) <= tol]
        if near:
            targets[k] = min(near, key=lambda b, tk=t_out[k]: abs(b - tk))
    return targets


def test_schedule_targets_equal_a_plain_loop():
    rng = np.random.default_rng(7)
    for _ in range(400):
        t_out = np.unique(np.round(np.cumsum(rng.uniform(0.01, 1.0, rng.integers(1, 40))), 2))
        tol = time_tolerance(float(t_out[0]), float(t_out[-1]))
        bps = list(rng.uniform(-1.0, t_out[-1] + 1.0, rng.integers(0, 6)))
        for _ in range(rng.integers(0, 6)):  # on, just inside and just outside an output time
            k = rng.integers(0, t_out.size)
            bps.append(float(t_out[k]) + tol * rng.choice([0.0, 0.5, -0.5, 0.99, 1.5, -2.0]))
        if t_out.size > 2:
            bps.append(math.fsum(t_out[1:3]) / 2)  # between two output times
        s = schedule(t_out, bps)
        assert s.targets.tobytes() == _loop_targets(s.t_out, s.breaks, s.tol).tobytes()
