"""Compiling the core's loops with numba, and where their machine code is cached: `jit`.

Every compiled function of the core is decorated with `jit`: ``numba.njit`` without fastmath
(IEEE arithmetic in the order written, nothing reassociated or contracted) and with numpy's
error model (x / 0 is inf or nan as in numpy, not an exception). A function is compiled at
its first call in a process (the kernels of `kepler`, `propagation` and `batch_ekf` take 4
to 7 s in all; its callers hand it C-contiguous float64 arrays, `f64`, so once each) unless
numba's on-disk cache holds it (about 0.2 s to load).

Where the cache is
    ``$XDG_CACHE_HOME/ssa_fusion/numba/<digest>`` (``~/.cache/ssa_fusion/numba/<digest>``
    without ``XDG_CACHE_HOME``), or ``$NUMBA_CACHE_DIR/ssa_fusion/<digest>`` when the user
    set ``NUMBA_CACHE_DIR``: outside the source tree, owned by the user. numba's cache index
    is a pickle, unpickled when a kernel is loaded, so a cache directory someone else can
    write would run their code: the directory is created with mode 0700, and it is used
    only while it and the ``ssa_fusion`` directories above it are owned by the user and
    writable by no one else. Otherwise, or where it cannot be created, the kernels are
    compiled in every process (a few seconds), never loaded from elsewhere (numba's own
    fallback, the ``__pycache__`` next to the source, is not used).

What names it
    ``<digest>``: the first 16 hex digits of the SHA-256 of what a module's machine code
    depends on, computed at import when its first function is decorated: the numba and
    Python versions, the text of the module's source file and of every module whose
    compiled functions it can call (the modules of the numba functions among its globals,
    transitively), and the values of those modules' constants (numbers, strings, tuples,
    arrays: numba freezes global values into the machine code). numba itself checks a
    cached kernel against its own source file only; keyed this way, the edit of a callee
    in another file, or of an imported constant, gives a new directory, so a stale kernel
    is never loaded, and nothing is kept by hand. Directories of older sources are never
    read again: deleting ``~/.cache/ssa_fusion/numba`` is always safe.

A compiled function calls the compiled functions of another module by the names it imports
(``from .kepler import _kepler_kernel``), or through a module whose globals hold them;
both are followed.
"""

from __future__ import annotations

import hashlib
import os
import stat
import sys
from collections.abc import Callable, Mapping
from pathlib import Path
from types import ModuleType
from typing import Any, TypeVar, cast

import numba
import numpy as np
from numba.core.dispatcher import Dispatcher
from numpy.typing import NDArray

__all__ = ["cache_directory", "cache_root", "f64", "jit", "jit_nogil", "source_digest"]

_Fn = TypeVar("_Fn", bound=Callable[..., Any])

_SCALARS = (bool, int, float, complex, str, bytes, type(None))

_NUMBA_CONFIG: Any = numba.config
"""numba's settings (``CACHE_DIR`` is set there from the environment, untyped)."""

_digests: dict[str, str | None] = {}
"""Digest per module name (`source_digest`), computed once per process."""


def cache_root() -> Path | None:
    """Return the directory that holds the core's cache directories (module docstring).

    None when there is none (no home directory).
    """
    env = os.environ.get("NUMBA_CACHE_DIR", "")
    if env:
        return Path(env).absolute() / "ssa_fusion"
    xdg = os.environ.get("XDG_CACHE_HOME", "")
    if xdg and os.path.isabs(xdg):  # a relative one is invalid (XDG base directory spec)
        return Path(xdg) / "ssa_fusion" / "numba"
    try:
        return Path.home() / ".cache" / "ssa_fusion" / "numba"
    except RuntimeError:  # no HOME and no password entry
        return None


def _constant(value: object) -> str | None:
    """Return a text standing for a global value numba would freeze, or None (not one)."""
    if isinstance(value, _SCALARS):
        return repr(value)
    if isinstance(value, tuple) and all(isinstance(v, _SCALARS) for v in value):
        return repr(value)
    if isinstance(value, np.ndarray):
        data = np.ascontiguousarray(value).tobytes()
        return f"{value.dtype}{value.shape}{hashlib.sha256(data).hexdigest()}"
    return None


def _holds_compiled(namespace: Mapping[str, Any]) -> bool:
    return any(isinstance(v, Dispatcher) for v in namespace.values())


def _gather(namespace: Mapping[str, Any], files: dict[str, bytes], constants: dict[str, str],
            seen: set[str]) -> None:
    """Add a module's source text and constants, and those of the modules it can call."""
    name = str(namespace.get("__name__", ""))
    if name in seen:
        return
    seen.add(name)
    path = namespace.get("__file__")
    if not isinstance(path, str):
        raise OSError(f"module {name} has no source file")
    files[name] = Path(path).read_bytes()
    for key, value in list(namespace.items()):
        if key.startswith("__"):
            continue
        if isinstance(value, Dispatcher):
            _gather(value.py_func.__globals__, files, constants, seen)
        elif isinstance(value, ModuleType):
            if _holds_compiled(vars(value)):
                _gather(vars(value), files, constants, seen)
        else:
            text = _constant(value)
            if text is not None:
                constants[f"{name}.{key}"] = text


def source_digest(fn: Callable[..., Any]) -> str | None:
    """Return the cache key of the module of ``fn`` (module docstring), or None.

    None when a source file cannot be read (a frozen install): then nothing is cached.
    Computed once per module and process, when its first function is decorated (imports
    stand at the top of a module, so every callee in another module is known then).
    """
    module = str(fn.__module__)
    if module not in _digests:
        files: dict[str, bytes] = {}
        constants: dict[str, str] = {}
        try:
            _gather(fn.__globals__, files, constants, set())
        except OSError:
            _digests[module] = None
            return None
        h = hashlib.sha256(f"numba {numba.__version__}; python {sys.version}\n".encode())
        for name in sorted(files):
            h.update(f"{name} {len(files[name])}\n".encode())
            h.update(files[name])
        for key in sorted(constants):
            h.update(f"{key}={constants[key]}\n".encode())
        _digests[module] = h.hexdigest()[:16]
    return _digests[module]


def _private(path: Path) -> bool:
    """Return whether ``path`` is a directory of this user that no one else may write."""
    try:
        st = path.lstat()
    except OSError:
        return False
    return (stat.S_ISDIR(st.st_mode) and st.st_uid == os.getuid()
            and not st.st_mode & (stat.S_IWGRP | stat.S_IWOTH))


def cache_directory(fn: Callable[..., Any]) -> Path | None:
    """Return the cache directory of ``fn``'s module, created if need be, or None.

    None (nothing cached) when there is no cache root or digest, or the directory cannot be
    created, or it or an ``ssa_fusion`` directory above it is not private to the user.
    """
    root, digest = cache_root(), source_digest(fn)
    if root is None or digest is None:
        return None
    directory = root / digest
    try:
        directory.mkdir(mode=0o700, parents=True, exist_ok=True)
    except OSError:
        return None
    ours = [directory, root] + ([root.parent] if root.name == "numba" else [])  # .../ssa_fusion
    return directory if all(_private(p) for p in ours) else None


def _compile(fn: _Fn, nogil: bool) -> _Fn:
    """Compile ``fn`` as `jit` does; ``nogil``: release the GIL while it runs."""
    directory = cache_directory(fn)
    if directory is not None:
        saved = _NUMBA_CONFIG.CACHE_DIR
        _NUMBA_CONFIG.CACHE_DIR = str(directory)  # read by numba's locator when decorating
        try:
            compiled = numba.njit(cache=True, error_model="numpy", nogil=nogil)(fn)
        except RuntimeError:  # numba: "cannot cache function ...: no locator available"
            compiled = None
        finally:
            _NUMBA_CONFIG.CACHE_DIR = saved
        path = getattr(getattr(compiled, "_cache", None), "cache_path", None)
        if isinstance(path, str) and Path(path).parent == directory:
            return cast(_Fn, compiled)
    return cast(_Fn, numba.njit(error_model="numpy", nogil=nogil)(fn))


def jit(fn: _Fn) -> _Fn:
    """Compile ``fn`` with numba (no fastmath, numpy's error model), cached (module docstring)."""
    return _compile(fn, nogil=False)


def jit_nogil(fn: _Fn) -> _Fn:
    """Compile ``fn`` as `jit`, releasing the GIL while it runs (threads run it at once)."""
    return _compile(fn, nogil=True)


def f64(a: NDArray[Any]) -> NDArray[np.float64]:
    """Return ``a`` as a C-contiguous writable float64 array (the kernels' argument type).

    ``a`` itself when it is one (the usual case, checked faster than ``np.require``), else a
    copy: one array type per argument, so each kernel is compiled once.
    """
    if a.dtype == np.float64 and a.flags.c_contiguous and a.flags.writeable:
        return a
    out: NDArray[np.float64] = np.array(a, dtype=np.float64, order="C")
    return out

