"""Importing ssa_fusion does no work: importing every module leaves the process
environment, the SIGINT/SIGTERM handlers and matplotlib's backend as they were. The node
executables set up the handlers and the BLAS thread limit (`ssa_fusion.nodes.start_process`)
before numpy is imported, so every BLAS library a node loads runs one thread."""

import json
import os
import subprocess
import sys
import textwrap
from importlib.metadata import entry_points

import pytest

THREAD_VARS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")

IMPORT_ALL = textwrap.dedent("""
    import importlib, json, os, pkgutil, signal, sys
    import matplotlib

    SIGNALS = (signal.SIGINT, signal.SIGTERM)

    def handlers():
        return {int(s): repr(signal.getsignal(s)) for s in SIGNALS}

    def backend():  # as set, without resolving an automatic choice
        return repr(dict.__getitem__(matplotlib.rcParams, "backend"))

    env, sig, mpl = dict(os.environ), handlers(), backend()
    import ssa_fusion

    names, failed = ["ssa_fusion"], {}
    for info in pkgutil.walk_packages(ssa_fusion.__path__, "ssa_fusion.",
                                      onerror=lambda name: None):
        names.append(info.name)
    for name in names:
        try:
            importlib.import_module(name)
        except ModuleNotFoundError as exc:
            failed[name] = exc.name or ""
    env_after = dict(os.environ)
    print(json.dumps({
        "imported": [n for n in names if n not in failed],
        "failed": failed,
        "env_changed": sorted(k for k in env.keys() | env_after.keys()
                              if env.get(k) != env_after.get(k)),
        "handlers_before": sig,
        "handlers_after": handlers(),
        "backend_before": mpl,
        "backend_after": backend(),
    }))
""")


def _clean_env() -> dict[str, str]:
    """This environment without the BLAS thread variables (conftest sets them; a module
    that set them at import would otherwise go unnoticed) and without a ROS domain."""
    return {k: v for k, v in os.environ.items()
            if k not in THREAD_VARS and k != "ROS_DOMAIN_ID"}


def _run(code: str) -> dict:
    done = subprocess.run([sys.executable, "-c", code], env=_clean_env(), capture_output=True,
                          text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.splitlines()[-1])


def test_importing_every_module_changes_no_environment_and_no_signal_handler():
    result = _run(IMPORT_ALL)
    # only a missing ssa_fusion_msgs (not built) may keep a module from importing
    others = {m: n for m, n in result["failed"].items() if not n.startswith("ssa_fusion_msgs")}
    assert not others, f"modules that do not import: {others}"
    if result["failed"]:
        pytest.skip(f"ssa_fusion_msgs missing; not imported: {sorted(result['failed'])}")
    assert "ssa_fusion.nodes.filter" in result["imported"]
    assert "ssa_fusion.apps.cli" in result["imported"]
    assert len(result["imported"]) > 40
    assert result["env_changed"] == []
    assert result["handlers_after"] == result["handlers_before"]
    assert result["backend_after"] == result["backend_before"]


def test_node_executables_prepare_the_process_before_numpy_is_imported():
    """The executables run `nodes.entry`, which imports nothing heavy; `start_process` then
    limits BLAS to one thread and installs the handlers; the node module imported after it
    (numpy, scipy.linalg) gets one thread per BLAS library."""
    scripts = {e.name: e.value for e in entry_points(group="console_scripts")
               if e.value.startswith("ssa_fusion.nodes")}
    assert scripts == {"sensor_sim": "ssa_fusion.nodes.entry:sensor_sim",
                       "surrogate": "ssa_fusion.nodes.entry:surrogate",
                       "filter": "ssa_fusion.nodes.entry:filter_node",
                       "recorder": "ssa_fusion.nodes.entry:recorder",
                       "foxglove_bridge": "ssa_fusion.nodes.entry:foxglove_bridge",
                       "catalog_filter": "ssa_fusion.nodes.entry:catalog_filter",
                       "catalog_surrogate": "ssa_fusion.nodes.entry:catalog_surrogate",
                       "conjunction": "ssa_fusion.nodes.entry:conjunction"}
    result = _run(textwrap.dedent("""
        import json, signal, sys
        import ssa_fusion.nodes.entry as entry
        light = "numpy" not in sys.modules and "rclpy" not in sys.modules
        entry.start_process()
        import ssa_fusion.nodes.filter, ssa_fusion.nodes.surrogate, ssa_fusion.nodes.sensor_sim
        import scipy.linalg
        from threadpoolctl import threadpool_info
        print(json.dumps({
            "light": light,
            "threads": [(i["filepath"], i["num_threads"]) for i in threadpool_info()],
            "handler": signal.getsignal(signal.SIGTERM).__name__,
        }))
    """))
    assert result["light"], "importing nodes.entry imports numpy or rclpy"
    assert result["threads"], "no BLAS library found"
    assert all(n == 1 for _, n in result["threads"]), result["threads"]
    assert result["handler"] == "_on_signal"


def test_a_catalog_filter_imports_neither_scipy_stats_nor_scipy_optimize():
    """Every catalog_filter process imports the association (`core.catalog.association`); of scipy
    it needs only scipy.special until an unlabelled detection arrives: scipy.stats and
    scipy.optimize would add ~45 MiB to each process (`core.catalog.association` docstring)."""
    result = _run(textwrap.dedent("""
        import json, sys
        import ssa_fusion.nodes.catalog_filter
        print(json.dumps(sorted(m for m in sys.modules if m.startswith("scipy."))))
    """))
    assert "scipy.special" in result
    heavy = [m for m in result if m.split(".")[1] in ("stats", "optimize", "sparse")]
    assert heavy == [], heavy
