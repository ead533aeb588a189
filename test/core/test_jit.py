"""`core.base.jit`: the compiled kernels' cache lives outside the source tree, in a directory
private to the user, named by a digest of the sources (callees in other modules included)
that nobody keeps by hand."""

from __future__ import annotations

import importlib
import os
import stat
import sys
from pathlib import Path

import pytest

from ssa_fusion.core.base import jit
from ssa_fusion.core.catalog import bank_kernels
from ssa_fusion.core.motion import kepler, propagation

PACKAGE = Path(jit.__file__).resolve().parents[1]

CALLEE = '''
from ssa_fusion.core.base.jit import jit

SCALE = {scale}


@jit
def twice(x: float) -> float:
    return SCALE * x
'''

CALLER = '''
from ssa_fusion.core.base.jit import jit
from {callee} import twice


@jit
def four_times(x: float) -> float:
    return twice(twice(x))
'''


def test_kernels_are_cached_outside_the_source_tree_in_a_private_directory():
    root = jit.cache_root()
    if root is None:
        pytest.skip("no home directory: nothing is cached")
    for kernel in (kepler._kepler_kernel, propagation._gravity_stm_kernel,
                   bank_kernels.update_kernel, bank_kernels.kepler_step_kernel):
        path = kernel._cache.cache_path
        if path is None:
            pytest.skip(f"no private cache directory under {root}: compiled in each process")
        directory = Path(path).parent
        assert directory.parent == root and len(directory.name) == 16
        assert PACKAGE not in Path(path).resolve().parents
        for d in (directory, root):
            st = d.stat()
            assert st.st_uid == os.getuid() and not st.st_mode & (stat.S_IWGRP | stat.S_IWOTH)


def _modules(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, scale: float):
    """(callee, caller) modules written to tmp_path and imported (again), fresh digests."""
    names = (f"jit_callee_{tmp_path.name}", f"jit_caller_{tmp_path.name}")
    (tmp_path / f"{names[0]}.py").write_text(CALLEE.format(scale=scale))
    (tmp_path / f"{names[1]}.py").write_text(CALLER.format(callee=names[0]))
    monkeypatch.syspath_prepend(str(tmp_path))
    out = []
    for name in names:
        jit._digests.pop(name, None)
        mod = sys.modules.get(name)
        out.append(importlib.reload(mod) if mod else importlib.import_module(name))
    return out


def test_the_key_follows_a_callee_in_another_module(tmp_path, monkeypatch):
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "cache"))
    _, caller = _modules(tmp_path, monkeypatch, 2.0)
    key = jit.source_digest(caller.four_times.py_func)
    assert caller.four_times(1.5) == 6.0
    directory = tmp_path / "cache" / "ssa_fusion" / key
    assert Path(caller.four_times._cache.cache_path).parent == directory
    assert any(directory.rglob("*.nbi"))  # numba's index, written after compiling
    assert stat.S_IMODE(directory.stat().st_mode) == 0o700
    # the same sources: the same key (nothing is recompiled in the next process)
    assert jit.source_digest(_modules(tmp_path, monkeypatch, 2.0)[1].four_times.py_func) == key
    # a change in the callee's module (a constant) changes the caller's key
    _, caller = _modules(tmp_path, monkeypatch, 3.0)
    assert jit.source_digest(caller.four_times.py_func) != key
    assert caller.four_times(1.5) == 13.5


def test_a_cache_directory_others_may_write_is_not_used(tmp_path, monkeypatch):
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "cache"))
    _, caller = _modules(tmp_path, monkeypatch, 2.0)
    directory = Path(caller.four_times._cache.cache_path).parent
    directory.chmod(0o777)
    assert jit.cache_directory(caller.four_times.py_func) is None
    _, caller = _modules(tmp_path, monkeypatch, 2.0)
    assert caller.four_times._cache.cache_path is None  # compiled, never loaded from there
    assert caller.four_times(1.0) == 4.0
