"""The numerical core gives the same results whichever OpenBLAS kernel runs it.

OpenBLAS picks its kernels (Haswell, SkylakeX, Zen, Sandybridge, ...) by CPU, and each
rounds differently. Every kernel this machine's OpenBLAS runs correctly (probed in a
subprocess with ``OPENBLAS_CORETYPE``; a kernel the CPU lacks instructions for, e.g.
SkylakeX without AVX-512, dies with SIGILL and is left out) is used to
(1) compute Hankel-DMD forecasts of reference cases, which must agree with every other
kernel's to ``FORECAST_RTOL`` of the data's scale, with the same rank; and
(2) run the core numerical tests of the surrogate and Hankel-DMD under one kernel other than
this process's: the oldest that runs here (``OLDEST_FIRST``: Prescott, SSE3 only, no AVX and
no FMA), the one whose rounding is farthest from the AVX2/AVX-512 FMA kernels a machine of
today picks. Each re-run is a whole pytest process (~8 s on 2 busy cores); (1) already
compares every kernel, so a second re-run under a middle kernel adds little.

Where the machine itself sets ``OPENBLAS_CORETYPE`` (its OpenBLAS needs it there), the
kernel is not changed and these tests are skipped.
"""

from __future__ import annotations

import functools
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

HERE = Path(__file__).resolve().parent
WORKER = HERE / "blas_kernel_worker.py"
# x86-64 kernels OpenBLAS's dynamic builds offer, newest first (others map onto these).
CANDIDATES = ("SkylakeX", "Haswell", "Zen", "Prescott", "Sandybridge", "Nehalem")
FORECAST_RTOL = 1e-6  # of max |z|: ~7 m on an ISS orbit; measured up to 1.2e-7
OLDEST_FIRST = ("Prescott", "Nehalem", "Sandybridge", "Zen", "Haswell", "SkylakeX")
"""The candidates oldest first (fewest instructions): the core tests re-run under the first
that runs here and is not this process's kernel."""

pytestmark = pytest.mark.skipif(
    "OPENBLAS_CORETYPE" in os.environ,
    reason="OPENBLAS_CORETYPE is set by this machine; its kernel is not changed in tests")


def _env(core: str) -> dict[str, str]:
    env = dict(os.environ, OPENBLAS_CORETYPE=core, OPENBLAS_NUM_THREADS="1")
    env["PYTHONPATH"] = os.pathsep.join([str(HERE.parents[1]), env.get("PYTHONPATH", "")])
    return env


@functools.cache
def kernels() -> dict[str, str]:
    """Kernel name as OpenBLAS reports it -> an OPENBLAS_CORETYPE that selects it."""
    found: dict[str, str] = {}
    for core in CANDIDATES:
        p = subprocess.run([sys.executable, str(WORKER), "probe"], env=_env(core),
                           capture_output=True, text=True, timeout=120)
        if p.returncode == 0:
            for arch in json.loads(p.stdout):
                found.setdefault(arch, core)
    return found


def _native() -> set[str]:
    import threadpoolctl

    return {i.get("architecture", "?") for i in threadpoolctl.threadpool_info()
            if i.get("internal_api") == "openblas"}


def test_at_least_two_kernels_run_here() -> None:
    assert len(kernels()) >= 2, f"only {kernels()} ran: nothing to compare"


def test_hankel_dmd_forecasts_agree_across_kernels(tmp_path: Path) -> None:
    results = {}
    for arch, core in kernels().items():
        out = tmp_path / f"{arch}.npz"
        subprocess.run([sys.executable, str(WORKER), "forecast", str(out)], env=_env(core),
                       check=True, timeout=300)
        results[arch] = dict(np.load(out))
    ref_arch, ref = next(iter(results.items()))
    names = [k for k in ref if ":" not in k]
    assert len(names) == 4
    for arch, res in results.items():
        for name in names:
            assert res[name + ":rank"] == ref[name + ":rank"], (name, arch, ref_arch)
            diff = np.abs(res[name] - ref[name]).max() / ref[name + ":scale"]
            assert diff < FORECAST_RTOL, f"{name}: {arch} vs {ref_arch}: {diff:.2e}"


def test_core_numerical_tests_pass_under_other_kernels() -> None:
    others = [core for arch, core in kernels().items() if arch not in _native()]
    assert others, "no kernel other than this process's runs here"
    for core in sorted(others, key=OLDEST_FIRST.index)[:1]:
        p = subprocess.run(
            [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
             str(HERE / "test_hankel_dmd.py"), str(HERE / "test_surrogate.py")],
            env=_env(core), capture_output=True, text=True, timeout=600)
        assert p.returncode == 0, f"OPENBLAS_CORETYPE={core}:\n{p.stdout[-3000:]}"
