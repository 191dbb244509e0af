"""CasADi C code generation, gcc compilation and a content-addressed build cache.

One :class:`CodegenSettings` holds every option that shapes the generated code and
the compiled library (acados-style: one place). :func:`build_library` turns CasADi
Functions into a shared library under ``<build root>/<sha256>/`` where the key is
the SHA-256 of everything that produced it: the generated C text, the compiler's
path and version, the flags, the CasADi version and the settings. An unchanged
model is never rebuilt; a changed one gets a new key, so it is never served stale.
A library is built in a temporary folder and renamed into place, so a cache entry
is either complete or absent.

Facts this module relies on (measured with CasADi 3.8.2): an external Function used
as an integrator's DAE must have exactly the inputs (t, x, z, p, u) and outputs
(ode, alg, quad, zero), and the same library must contain ``jac_<name>`` generated
with ``f.jacobian()`` (direct Newton) or ``fwd1_<name>`` (``f.forward(1)``, GMRES).
Without ``jac_<name>`` the external must carry its Jacobian's sparsity pattern
(``CodeGenerator.add(f, True)``), else CasADi's CVODES/IDAS set-up allocates a dense
nx×nx matrix (N = 500: 2.8 GB, ≈ 400 s; see docs/performance.md).
"""

from __future__ import annotations

import ctypes
import functools
import hashlib
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import casadi as ca
from platformdirs import user_cache_dir

from core import artifacts
from core.artifacts import sha256_file
from core.errors import BuildError

#: default cache root: the user's cache folder (``$XDG_CACHE_HOME`` or ``~/.cache`` on
#: Linux), outside the package, so an installed package never writes into site-packages;
#: ``HITL_BUILD_DIR`` overrides it
DEFAULT_BUILD_ROOT = Path(user_cache_dir("hitl-formation")) / "build"
#: names of what a cache root holds: entries (64 hex digits), failed sources, the start-up
#: caches of core/models/cache.py (gains, models), temp folders
ENTRY_PATTERN = re.compile(r"[0-9a-f]{64}|failed|gains|models|\.tmp-.*")
JACOBIAN_STRATEGIES = ("sparse", "gmres", "jvp")
#: ``auto`` is resolved from the number of agents by :func:`generated.largescale.choose_plan`
#: before anything is generated
JACOBIAN_CHOICES = ("auto", *JACOBIAN_STRATEGIES)
SOURCE_NAME = "model.c"
LIBRARY_NAME = "model.so"
MANIFEST_NAME = "manifest.json"
#: temporary build folders: ``.tmp-<key[:12]>-<pid>-<random>``
TMP_PREFIX = ".tmp-"


@dataclass(frozen=True)
class CodegenSettings:
    """Every option of code generation, compilation and the integrators' linear algebra.

    Attributes
    ----------
    compiler : str
        C compiler executable (``gcc``; ``cc``/``clang`` work too).
    optimization : str
        Optimisation flag. ``-O1`` is the default: ``-O0`` compiles 3–4× faster on
        large files but the right-hand side then runs slower.
    extra_cflags : tuple of str
        Appended after the fixed flags ``-shared -fPIC``.
    jacobian : str
        ``"sparse"``: ``jac_<name>`` from ``f.jacobian()`` (CasADi's sparse CCS pattern)
        with a direct sparse linear solver; ``"gmres"``: additionally
        ``fwd1_<name>`` (``f.forward(1)``, Jacobian-vector products) and the
        integrators' iterative ``newton_scheme = "gmres"`` (no factorisation, for
        large N); ``"jvp"``: only ``fwd1_<name>`` and GMRES (no Jacobian generated at
        all: code size flat in N with ``expand=False``; the fixed-step method then
        builds its Jacobian from forward sweeps).
    linear_solver : str
        Direct sparse linear solver of CVODES/IDAS and of the fixed-step method
        (a CasADi Linsol plugin: ``csparse``, ``qr``, ``ldl``, ``lapacklu`` (dense)).
    expand : bool
        Expand MX Functions to SX before generating code (flat, faster C).
    cse : bool
        Common-subexpression elimination (CasADi's ``cse`` option) on SX functions and
        their generated Jacobians before code is written. Same operations on the same
        operands, so the same results; measured on the paper scenario (N = 5): the
        right-hand side 2,723 → 1,721 instructions, its Jacobian 27,298 → 17,557.
    build_root : str or None
        Cache root; ``None`` = ``$HITL_BUILD_DIR`` or :data:`DEFAULT_BUILD_ROOT`.
    timeout : float
        Seconds allowed for one compilation.
    codegen_options : tuple of (str, value) pairs
        Options for :class:`casadi.CodeGenerator`.
    """

    compiler: str = "gcc"
    optimization: str = "-O1"
    extra_cflags: tuple[str, ...] = ()
    jacobian: str = "sparse"
    linear_solver: str = "csparse"
    expand: bool = True
    cse: bool = True
    build_root: str | None = None
    timeout: float = 900.0
    codegen_options: tuple[tuple[str, Any], ...] = field(default=(("with_header", False),))

    def __post_init__(self) -> None:
        if self.jacobian not in JACOBIAN_CHOICES:
            raise BuildError(
                f"CodegenSettings.jacobian: {self.jacobian!r} is not allowed "
                f"(expected one of {', '.join(JACOBIAN_CHOICES)})"
            )
        if not ca.has_linsol(self.linear_solver):
            raise BuildError(
                f"CodegenSettings.linear_solver: {self.linear_solver!r} is not a CasADi "
                "linear solver plugin (expected csparse, qr, ldl or lapacklu)"
            )

    @property
    def cflags(self) -> tuple[str, ...]:
        """The complete compiler flags, in order."""
        return ("-shared", "-fPIC", self.optimization, *self.extra_cflags)

    def root(self) -> Path:
        """The cache root folder."""
        return Path(self.build_root) if self.build_root is not None else default_build_root()

    def integrator_options(self) -> dict[str, Any]:
        """The CVODES/IDAS options that follow from the Jacobian strategy.

        Those of :func:`generated.largescale.choose_plan` (the one place that maps a
        strategy to solver options; ``jvp`` adds ``use_preconditioner=False`` and
        ``max_krylov``).

        Raises
        ------
        BuildError
            For ``jacobian="auto"`` (it depends on N: resolve it first).
        """
        from generated.largescale import choose_plan  # largescale imports this module

        if self.jacobian not in JACOBIAN_STRATEGIES:
            raise BuildError(
                f"CodegenSettings.jacobian: {self.jacobian!r} depends on N "
                "(resolve it with generated.largescale.choose_plan(N))"
            )
        return choose_plan(1, self.jacobian, linear_solver=self.linear_solver).integrator_options

    def key_fields(self) -> dict[str, Any]:
        """The settings that enter the cache key (the build root does not)."""
        d = asdict(self)
        d.pop("build_root")
        d.pop("timeout")
        d["codegen_options"] = [list(p) for p in self.codegen_options]
        return d


@dataclass(frozen=True)
class Toolchain:
    """What a library needs beyond the generated code (the native integrator's driver).

    Attributes
    ----------
    appended_source : str
        C text appended to the generated code (one translation unit, so it can call
        the generated functions directly).
    include_dirs : tuple of Path
        ``-I`` folders.
    libraries : tuple of Path
        Shared libraries linked after the source, in dependency order. The library
        records only their sonames (no rpath): they are loaded by absolute path from the
        running environment before it (:func:`preload`), so a cache entry does not
        depend on the checkout or environment that built it.
    key : mapping
        What else identifies the build (hashes of headers and libraries): part of the
        cache key, so that a changed header or library is never served from the cache.
    """

    appended_source: str = ""
    include_dirs: tuple[Path, ...] = ()
    libraries: tuple[Path, ...] = ()
    key: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class Library:
    """A compiled shared library and how it was obtained.

    Attributes
    ----------
    key : str
        SHA-256 cache key (the folder name).
    folder, source, path : Path
        The cache folder, the generated C file and the shared library.
    names : tuple of str
        Functions in the library (with their ``jac_``/``fwd1_`` companions).
    cache_hit : bool
        True when the library was reused, not compiled.
    codegen_seconds, compile_seconds : float
        Wall time of C generation and of compilation (0 on a cache hit).
    source_bytes : int
        Size of the generated C.
    preload : tuple of Path
        Shared libraries it needs loaded first (:attr:`Toolchain.libraries`).
    """

    key: str
    folder: Path
    source: Path
    path: Path
    names: tuple[str, ...]
    cache_hit: bool
    codegen_seconds: float
    compile_seconds: float
    source_bytes: int
    preload: tuple[Path, ...] = ()

    def function(self, name: str) -> ca.Function:
        """Load ``name`` from the library with :func:`casadi.external`.

        Parameters
        ----------
        name : str
            One of :attr:`names`.

        Raises
        ------
        BuildError
            If the library has no function ``name``.
        """
        if name not in self.names:
            raise BuildError(
                f"library {self.path}: no function {name!r} (it has {', '.join(self.names)})"
            )
        preload(self.preload)
        return ca.external(name, str(self.path))


# --------------------------------------------------------------------------- helpers
def default_build_root() -> Path:
    """The cache root without settings: ``$HITL_BUILD_DIR``, else :data:`DEFAULT_BUILD_ROOT`."""
    env = os.environ.get("HITL_BUILD_DIR")
    return Path(env) if env else DEFAULT_BUILD_ROOT


def clear_cache(root: Path | None = None) -> list[Path]:
    """Remove the build cache's entries, failed sources and temporary folders.

    Only names the cache itself creates (:data:`ENTRY_PATTERN`) are removed, so a
    root pointed at a folder with other content loses nothing else; the root itself
    is removed when it is left empty.

    Parameters
    ----------
    root : Path, optional
        Default :func:`default_build_root`.

    Returns
    -------
    list of Path
        What was removed.
    """
    root = root if root is not None else default_build_root()
    if not root.is_dir():
        return []
    removed = []
    for d in sorted(root.iterdir()):
        if d.is_dir() and not d.is_symlink() and ENTRY_PATTERN.fullmatch(d.name):
            shutil.rmtree(d, ignore_errors=True)
            removed.append(d)
    if not any(root.iterdir()):
        root.rmdir()
    return removed


@functools.lru_cache(maxsize=8)
def compiler_identity(compiler: str) -> str:
    """Resolved path and first ``--version`` line of ``compiler`` (part of the cache key).

    Parameters
    ----------
    compiler : str
        Executable name or path, looked up on ``PATH``.

    Raises
    ------
    BuildError
        If the compiler is not found.
    """
    path = shutil.which(compiler)
    if path is None:
        raise BuildError(
            f"CodegenSettings.compiler: {compiler!r} not found on PATH (install gcc or set compiler)"
        )
    try:
        out = subprocess.run(
            [path, "--version"], capture_output=True, text=True, timeout=60, check=False
        )
    except OSError as exc:
        raise BuildError(f"CodegenSettings.compiler: {path} cannot run ({exc.strerror})") from None
    first = (out.stdout or out.stderr).splitlines()
    return f"{os.path.realpath(path)} | {first[0] if first else 'unknown version'}"


def renamed(f: ca.Function, name: str, *, expand: bool = True, cse: bool = False) -> ca.Function:
    """``f`` under a new name with the same inputs/outputs (SX when possible).

    Parameters
    ----------
    f : casadi.Function
        The function to copy.
    name : str
        The new name.
    expand : bool
        Expand an MX ``f`` to SX; it stays MX if expansion fails or ``expand`` is False.
    cse : bool
        Eliminate common subexpressions of the SX result (no effect on MX).
    """
    fs = f if f.is_a("SXFunction") else (_expanded(f) if expand else None)
    if fs is not None:
        args = fs.sx_in()
        opts = {"cse": True} if cse else {}
        return ca.Function(name, args, fs.call(args), fs.name_in(), fs.name_out(), opts)
    args = f.mx_in()
    return ca.Function(name, args, f.call(args), f.name_in(), f.name_out())


def _expanded(f: ca.Function) -> ca.Function | None:
    try:
        return f.expand()
    except RuntimeError:  # e.g. calls an external or a Linsol: keep MX
        return None


def check_dyn_signature(f: ca.Function, what: str) -> None:
    """Raise :class:`BuildError` unless ``f`` has the integrator signature ``dyn_in -> dyn_out``.

    Parameters
    ----------
    f : casadi.Function
        The function to check.
    what : str
        How ``f`` is named in the error message.
    """
    if list(f.name_in()) != list(ca.dyn_in()) or list(f.name_out()) != list(ca.dyn_out()):
        raise BuildError(
            f"{what}: has inputs ({', '.join(f.name_in())}) and outputs "
            f"({', '.join(f.name_out())}); expected ({', '.join(ca.dyn_in())}) -> "
            f"({', '.join(ca.dyn_out())}) (build it with ca.dyn_in()/ca.dyn_out())"
        )


def generate_source(
    functions: Sequence[ca.Function],
    settings: CodegenSettings,
    with_derivatives: Sequence[str] = (),
) -> tuple[str, tuple[str, ...]]:
    """C source of ``functions`` plus, for the names in ``with_derivatives``, their Jacobians.

    Parameters
    ----------
    functions : sequence of casadi.Function
        Named functions to put in the library.
    settings : CodegenSettings
    with_derivatives : sequence of str
        Names whose ``jac_<name>`` (``f.jacobian()``, strategies sparse and gmres) and
        ``fwd1_<name>`` (``f.forward(1)``, strategies gmres and jvp) are generated as well;
        with ``jvp`` they also carry their Jacobian's sparsity pattern (no code, O(nnz)
        integers) so that CVODES/IDAS never allocate a dense nx×nx matrix.

    Returns
    -------
    (str, tuple of str)
        The C text and the names of all functions in it.
    """
    if settings.jacobian not in JACOBIAN_STRATEGIES:
        raise BuildError(
            f"CodegenSettings.jacobian: {settings.jacobian!r} must be resolved before "
            "generating code (generated.largescale.choose_plan(N).codegen_settings(...))"
        )
    cg = ca.CodeGenerator(SOURCE_NAME, dict(settings.codegen_options))
    names: list[str] = []
    seen: set[str] = set()
    for f in functions:
        if f.name() in seen:
            raise BuildError(f"generate_source: two functions are named {f.name()!r}")
        seen.add(f.name())
        derive = f.name() in with_derivatives
        # jvp: no jac_<name>, so the pattern must come with the function itself
        cg.add(f, derive and settings.jacobian == "jvp")
        names.append(f.name())
        if derive:
            if settings.jacobian in ("sparse", "gmres"):
                jac = f.jacobian()  # named jac_<name>, as the integrator plugins look it up
                if settings.cse and jac.is_a("SXFunction"):
                    jac = renamed(jac, jac.name(), cse=True)
                cg.add(jac)
                names.append(jac.name())
            if settings.jacobian in ("gmres", "jvp"):
                fwd = f.forward(1)
                cg.add(fwd)
                names.append(fwd.name())
    missing = set(with_derivatives) - seen
    if missing:
        raise BuildError(f"generate_source: with_derivatives names unknown {sorted(missing)}")
    return cg.dump(), tuple(names)


def cache_key(
    source: str, settings: CodegenSettings, extra: Mapping[str, Any] | None = None
) -> str:
    """SHA-256 of everything that produced a library.

    Parameters
    ----------
    source : str
        The complete C text.
    settings : CodegenSettings
        Its compiler identity, flags and key fields enter the key (not ``build_root``
        or ``timeout``); the CasADi version does too.
    extra : mapping, optional
        Further inputs of the build (e.g. the hash of included headers and the identity
        of linked libraries, :class:`Toolchain`).
    """
    ident = {
        "source_sha256": hashlib.sha256(source.encode()).hexdigest(),
        "compiler": compiler_identity(settings.compiler),
        "cflags": list(settings.cflags),
        "casadi": ca.__version__,
        "settings": settings.key_fields(),
    }
    if extra:
        ident["extra"] = dict(extra)
    blob = json.dumps(ident, sort_keys=True, default=str).encode()
    return hashlib.sha256(blob).hexdigest()


def compile_source(
    source: str, settings: CodegenSettings, folder: Path, toolchain: Toolchain | None = None
) -> float:
    """Write ``source`` to ``folder/model.c`` and compile ``folder/model.so``.

    Parameters
    ----------
    source : str
        The C text.
    settings : CodegenSettings
        Compiler, flags and timeout.
    folder : Path
        Output folder, created if missing.
    toolchain : Toolchain, optional
        Include folders and shared libraries to link (after the source, by soname and
        without an rpath: :attr:`Toolchain.libraries`).

    Returns
    -------
    float
        Compile wall time in seconds.

    Raises
    ------
    BuildError
        With the compiler's first error lines and the source path.
    """
    folder.mkdir(parents=True, exist_ok=True)
    src = folder / SOURCE_NAME
    artifacts.atomic_write_text(src, source)  # a failed write names the file
    tc = toolchain or Toolchain()
    cmd = [
        settings.compiler,
        *settings.cflags,
        *(f"-I{d}" for d in tc.include_dirs),
        str(src),
        "-o",
        str(folder / LIBRARY_NAME),
        *(str(lib) for lib in tc.libraries),  # DT_NEEDED = their sonames; no rpath
        "-lm",
    ]
    t0 = time.perf_counter()
    try:
        res = subprocess.run(
            cmd, capture_output=True, text=True, timeout=settings.timeout, check=False
        )
    except FileNotFoundError:
        raise BuildError(
            f"CodegenSettings.compiler: {settings.compiler!r} not found (install gcc or set compiler)"
        ) from None
    except subprocess.TimeoutExpired:
        raise BuildError(
            f"compiling {src} took longer than {settings.timeout:.0f} s "
            "(raise CodegenSettings.timeout or use optimization='-O0')"
        ) from None
    if res.returncode != 0:
        lines = [ln for ln in res.stderr.splitlines() if "error" in ln.lower()] or (
            res.stderr.splitlines() or [f"exit status {res.returncode}"]
        )
        raise BuildError(f"compiling {src} failed: " + " | ".join(lines[:3]))
    return time.perf_counter() - t0


def entry_problem(folder: Path, key: str) -> str | None:
    """Why the cache entry ``folder`` cannot be loaded for ``key`` (None: it can).

    The manifest must name ``key`` and record the SHA-256 of ``model.so``, and the
    library's bytes must have that hash: a truncated or corrupt file, or a library
    copied in from another build, is caught before it is ever loaded.

    Parameters
    ----------
    folder : Path
        ``<root>/<key>/``.
    key : str
        The key this build needs.
    """
    try:
        info = json.loads((folder / MANIFEST_NAME).read_text())
    except FileNotFoundError:
        return "no manifest (incomplete entry)"
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
        return "manifest unreadable"
    if not isinstance(info, dict) or not isinstance(info.get("library_sha256"), str):
        return "manifest records no library SHA-256"
    if info.get("key") != key:
        return f"manifest is for key {str(info.get('key'))[:12]}…, not this build"
    try:
        digest = sha256_file(folder / LIBRARY_NAME)
    except OSError:
        return f"{LIBRARY_NAME} missing or unreadable"
    if digest != info["library_sha256"]:
        return f"{LIBRARY_NAME} does not have the SHA-256 its manifest records (truncated, corrupt or replaced)"
    return None


@functools.lru_cache(maxsize=8)
def preload(libraries: tuple[Path, ...]) -> None:
    """Load shared libraries by absolute path, locally, once per process.

    A library linked against them names them only by soname (no rpath); the dynamic
    loader matches a NEEDED soname against the libraries already loaded, so loading
    these first lets it load from any checkout or environment. Locally (RTLD_LOCAL):
    loaded globally, their symbols would take precedence over those of the SUNDIALS
    that CasADi's own CVODES and IDAS plugins bring, which have the same names.

    Parameters
    ----------
    libraries : tuple of Path
        In dependency order (a library before those that need it).

    Raises
    ------
    OSError
        If one cannot be loaded.
    """
    for lib in libraries:
        ctypes.CDLL(str(lib), mode=ctypes.RTLD_LOCAL)


def load_problem(path: Path, libraries: Sequence[Path] = ()) -> str | None:
    """Why the shared library ``path`` cannot be loaded in this process (None: it can).

    ``libraries`` are preloaded (:func:`preload`), then ``path`` is opened with every
    symbol bound at once (ctypes' ``RTLD_NOW``) and closed again: a NEEDED library that
    is not found, an unresolved symbol or bytes that are no shared library are reported
    here instead of as a traceback of the first load.

    Parameters
    ----------
    path : Path
        The library.
    libraries : sequence of Path
        What it needs loaded first (:attr:`Toolchain.libraries`).
    """
    try:
        preload(tuple(libraries))
        handle = ctypes.CDLL(str(path))._handle
    except OSError as exc:
        return str(exc).replace(f"{path}: ", "")
    import _ctypes  # dlclose: the check keeps no mapping of the cache file

    _ctypes.dlclose(handle)
    return None


def remove_stale_builds(root: Path, min_age: float = artifacts.STALE_SECONDS) -> list[Path]:
    """Remove ``.tmp-<key>-<pid>-*`` build folders whose process is gone.

    A folder is stale when the PID in its name is not running, or (a name without a
    PID) when it is older than ``min_age`` seconds. A live build's folder is kept
    whatever its age (compiling N = 50 takes over ten minutes).

    Parameters
    ----------
    root : Path
        The cache root.
    min_age : float
        Age in seconds after which a folder without a PID counts as stale.

    Returns
    -------
    list of Path
        The folders removed.
    """
    removed = []
    for d in root.glob(f"{TMP_PREFIX}*"):
        m = re.fullmatch(re.escape(TMP_PREFIX) + r"[0-9a-f]+-(\d+)-.*", d.name)
        if artifacts.stale_temp(d, int(m.group(1)) if m else None, min_age):
            shutil.rmtree(d, ignore_errors=True)
            removed.append(d)
    return removed


def _install(tmp: Path, folder: Path) -> None:
    """Rename a complete build into place; a concurrent identical build may have won."""
    for _ in range(2):
        try:
            os.rename(tmp, folder)
            return
        except OSError:
            if entry_problem(folder, folder.name) is None:  # complete entry, other process
                shutil.rmtree(tmp, ignore_errors=True)
                return
            shutil.rmtree(folder, ignore_errors=True)  # incomplete or bad entry: never trusted
    os.rename(tmp, folder)


def build_library(
    functions: Sequence[ca.Function],
    settings: CodegenSettings | None = None,
    with_derivatives: Sequence[str] = (),
    toolchain: Toolchain | None = None,
) -> Library:
    """Generate, compile (or reuse from the cache) and describe a shared library.

    Parameters
    ----------
    functions : sequence of casadi.Function
        Functions to compile, under their own names.
    settings : CodegenSettings, optional
    with_derivatives : sequence of str
        Names that also get their derivative companions (see :func:`generate_source`).
    toolchain : Toolchain, optional
        Hand-written C appended to the generated code, include folders and libraries
        to link; its :attr:`Toolchain.key` enters the cache key.

    Returns
    -------
    Library

    Raises
    ------
    BuildError
        Compiler missing, compilation failed (first error lines and the source path;
        the failed source is kept under ``<root>/failed/<key>/``), or bad settings.
    """
    settings = settings or CodegenSettings()
    t0 = time.perf_counter()
    tc = toolchain or Toolchain()
    source, names = generate_source(functions, settings, with_derivatives)
    source += tc.appended_source
    t_codegen = time.perf_counter() - t0
    key = cache_key(source, settings, tc.key)
    root = settings.root()
    folder = root / key
    if root.is_dir():
        remove_stale_builds(root)
    hit = _usable_entry(folder, key, tc)
    t_compile = 0.0 if hit else _compile_entry(root, key, source, names, settings, tc)
    return Library(
        key,
        folder,
        folder / SOURCE_NAME,
        folder / LIBRARY_NAME,
        names,
        hit,
        t_codegen,
        t_compile,
        len(source),
        tuple(tc.libraries),
    )


def _usable_entry(folder: Path, key: str, tc: Toolchain) -> bool:
    """Whether the cache entry ``folder`` exists and may be loaded for ``key``.

    A bad entry is reported on stderr and never dlopen'ed: it would crash (truncated)
    or silently compute another model. An entry that checks out but cannot be loaded
    in this process (:func:`load_problem`) is reported in one line and moved aside, so
    that the rebuild replaces it.
    """
    if not folder.exists():
        return False
    why = entry_problem(folder, key)
    if why is not None:
        print(f"build cache {folder}: {why}; rebuilding", file=sys.stderr)
        return False
    why = load_problem(folder / LIBRARY_NAME, tc.libraries)
    if why is None:
        return True
    print(f"cache entry {key[:12]}: cannot be loaded here ({why}); rebuilding", file=sys.stderr)
    _discard(folder)
    return False


def _discard(folder: Path) -> None:
    """Remove a cache entry: renamed to a temporary name first, so it vanishes at once."""
    prefix = f"{TMP_PREFIX}{folder.name[:12]}-{os.getpid()}-"
    try:
        aside = Path(tempfile.mkdtemp(dir=folder.parent, prefix=prefix))
        os.rename(folder, aside)  # onto the empty folder just made
    except OSError:  # another process moved or replaced it
        return
    shutil.rmtree(aside, ignore_errors=True)


def _compile_entry(
    root: Path,
    key: str,
    source: str,
    names: tuple[str, ...],
    settings: CodegenSettings,
    tc: Toolchain,
) -> float:
    """Compile ``source`` in a temporary folder and install it as ``root/key``.

    Returns the compile wall time. On a compile failure the source is kept under
    ``root/failed/key/`` and the error names it.
    """
    root.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(dir=root, prefix=f"{TMP_PREFIX}{key[:12]}-{os.getpid()}-"))
    folder = root / key
    try:
        try:
            t_compile = compile_source(source, settings, tmp, tc)
        except BuildError as exc:
            failed = root / "failed" / key
            shutil.rmtree(failed, ignore_errors=True)
            failed.parent.mkdir(parents=True, exist_ok=True)
            os.replace(tmp, failed)
            raise BuildError(str(exc).replace(str(tmp), str(failed))) from None
        info = _manifest(key, tmp, names, settings, tc, len(source), t_compile)
        # the manifest is written last: its presence marks a complete entry
        text = json.dumps(info, indent=2, sort_keys=True, default=str)
        artifacts.atomic_write_text(tmp / MANIFEST_NAME, text)
        _install(tmp, folder)
    finally:
        if tmp.exists() and tmp != folder:
            shutil.rmtree(tmp, ignore_errors=True)
    return t_compile


def _manifest(
    key: str,
    folder: Path,
    names: tuple[str, ...],
    settings: CodegenSettings,
    tc: Toolchain,
    source_bytes: int,
    t_compile: float,
) -> dict[str, Any]:
    """The manifest of a compiled entry: its key, hashes and what built it."""
    return {
        "key": key,
        "library_sha256": sha256_file(folder / LIBRARY_NAME),
        "source_sha256": sha256_file(folder / SOURCE_NAME),
        "names": list(names),
        "compiler": compiler_identity(settings.compiler),
        "cflags": list(settings.cflags),
        "casadi": ca.__version__,
        "settings": settings.key_fields(),
        "toolchain": dict(tc.key),
        "source_bytes": source_bytes,
        "compile_seconds": t_compile,
    }
