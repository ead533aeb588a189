"""`ssa-fusion` command line: user mistakes get a one-line error and exit 2 (no traceback),
and `live` never overwrites an earlier run."""

import argparse
import json
import os
import signal
import time
import weakref
from pathlib import Path

import numpy as np
import pytest

from ssa_fusion.apps import args as cliargs
from ssa_fusion.apps import cli, live, runs

SAMPLE = str(Path(__file__).resolve().parents[2] / "bags" / "sample_iss_j2_rae")


@pytest.mark.parametrize("argv", [
    ["live", "--time-scale", "0"],
    ["live", "--time-scale", "-1"],
    ["live", "--time-scale", "fast"],
    ["replay", SAMPLE, "--rate", "-5"],
])
def test_bad_numbers_are_refused_by_the_parser(argv, capsys):
    with pytest.raises(SystemExit) as exc:
        cli.main(argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "must be a finite number > 0" in err or "is not a number" in err


def test_report_on_something_that_is_not_a_bag(tmp_path, capsys):
    assert cli.main(["report", str(tmp_path)]) == 2
    assert "not a rosbag2 directory" in capsys.readouterr().err
    assert cli.main(["report", str(tmp_path / "nope")]) == 2
    assert "no such bag" in capsys.readouterr().err


def test_reproduce_out_that_is_a_file(tmp_path, capsys):
    f = tmp_path / "file"
    f.write_text("x")
    assert cli.main(["reproduce", "--quick", "--scenario", "iss_j2_pos", "--out", str(f)]) == 2
    assert "cannot use --out" in capsys.readouterr().err


def test_offline_replay_never_overwrites(tmp_path, capsys):
    out = tmp_path / "exists"
    out.mkdir()
    assert cli.main(["replay", SAMPLE, "--offline", "--out", str(out)]) == 2
    assert "exists already" in capsys.readouterr().err


def test_live_runs_get_new_directories_and_a_latest_link(tmp_path):
    a = runs.default_out("iss_j2_rae", tmp_path)
    a.mkdir()
    runs.link_latest(a, tmp_path)
    b = runs.default_out("iss_j2_rae", tmp_path)  # same second: a suffix, never `a`
    assert b != a and b.name.startswith("iss_j2_rae_")
    b.mkdir()
    runs.link_latest(b, tmp_path)
    assert (tmp_path / "latest").resolve() == b.resolve()
    assert a.is_dir()  # the earlier run is kept


def test_domain_id_defaults_to_the_environment(monkeypatch):
    monkeypatch.setenv("ROS_DOMAIN_ID", "77")
    p = argparse.ArgumentParser()
    cliargs.add_domain_id(p)
    assert p.parse_args([]).domain_id == 77
    monkeypatch.delenv("ROS_DOMAIN_ID")
    p = argparse.ArgumentParser()
    cliargs.add_domain_id(p)
    assert p.parse_args([]).domain_id is None


def test_outputs_under_a_file_are_refused(tmp_path, capsys):
    f = tmp_path / "afile"
    f.write_text("x")
    assert cli.main(["live", "--out", str(f)]) == 2
    assert "cannot use" in capsys.readouterr().err
    assert cli.main(["replay", SAMPLE, "--offline", "--out", str(f / "x")]) == 2
    assert "cannot write" in capsys.readouterr().err


def test_reader_entries_name_a_node_and_a_topic():
    from ssa_fusion.params.checks import OUTPUT, check_needs
    from ssa_fusion.ros.readiness import OUTPUT as READINESS_OUTPUT
    from ssa_fusion.ros.readiness import READERS

    assert OUTPUT == READINESS_OUTPUT

    assert check_needs(READERS) is None
    assert "no namespace" in check_needs(["/ns/filter:/ssa/measurement"])
    assert "is not 'node:/topic'" in check_needs(["filter"])
    assert check_needs(["recorder:/ssa/estimate=4", "filter:>/ssa/estimate=2"]) is None
    for bad in ("recorder:/ssa/estimate=0", "recorder:/ssa/estimate=two",
                "recorder:/ssa/estimate=", "filter:>ssa/estimate", "filter:>/ssa/estimate=0"):
        assert "count: how many, at least 1" in check_needs([bad]), bad


def test_a_reader_with_a_count_waits_for_that_many_publishers():
    from types import SimpleNamespace

    from ssa_fusion.ros.readiness import MATCHED_KEY, ReadyNodes

    class _Node:
        def create_subscription(self, *_args):
            return None

    ready = ReadyNodes(_Node())

    def report(n: int) -> None:
        kv = SimpleNamespace(key=MATCHED_KEY + "/ssa/estimate", value=str(n))
        ready._on(SimpleNamespace(status=[SimpleNamespace(name="recorder", values=[kv])]))

    needs = ["recorder:/ssa/estimate=3", "recorder:/ssa/estimate"]
    report(1)
    assert ready.unmatched(needs) == ["recorder:/ssa/estimate=3"]
    report(3)
    assert ready.ready(needs)


def test_an_output_need_waits_for_the_writers_side_of_the_match():
    """'node:>/topic=n' reads the node's publisher-side count, not its subscription's."""
    from types import SimpleNamespace

    from ssa_fusion.ros.readiness import MATCHED_KEY, MATCHED_READERS_KEY, ReadyNodes

    class _Node:
        def create_subscription(self, *_args):
            return None

    ready = ReadyNodes(_Node())

    def report(readers: int, publishers: int) -> None:
        kvs = [SimpleNamespace(key=MATCHED_READERS_KEY + "/ssa/estimate", value=str(readers)),
               SimpleNamespace(key=MATCHED_KEY + "/ssa/estimate", value=str(publishers))]
        ready._on(SimpleNamespace(status=[SimpleNamespace(name="filter", values=kvs)]))

    needs = ["filter:>/ssa/estimate=2"]
    report(readers=1, publishers=5)  # its input's count does not stand in for its output's
    assert ready.unmatched(needs) == needs
    assert ready.ready(["filter:/ssa/estimate=5"])
    report(readers=2, publishers=0)
    assert ready.ready(needs) and not ready.ready(["filter:/ssa/estimate"])


class _FakeGraph:
    """Stands in for `ros.processes.Graph`: nodes 'run' and exit 0 at once."""

    def __init__(self, *_args, **_kwargs) -> None:
        self.domain_id = 0
        self.run = "20250101_000000_000_0000"

    def collect(self, *_args) -> list:
        return []

    def start_node(self, *_args, **_kwargs) -> object:
        return object()

    def wait_done_or_broken(self, *_args, **_kwargs) -> bool:
        return True

    def wait_quiet(self, *_args, **_kwargs) -> None:
        return None

    def close(self) -> list[str]:
        return []


def test_live_run_that_cannot_be_evaluated_says_why_without_a_traceback(tmp_path, monkeypatch,
                                                                         capsys):
    """A run whose bag has no outage (a real-sky seed where no pass was withheld) raised
    ValueError out of `live` with a traceback; now it is one line, exit 1, the bag kept."""
    from ssa_fusion.apps import evaluate

    monkeypatch.setattr(runs, "run_graph", _FakeGraph)
    monkeypatch.setattr(evaluate, "load", lambda _bag: evaluate.BagData(counts={"/clock": 3}))
    args = cli.build_parser().parse_args(["live", "--out", str(tmp_path / "run")])
    assert live.run(args) == 1
    err = capsys.readouterr().err
    assert "error: the run cannot be evaluated: the bag has no /ssa/truth messages" in err
    assert "recorded 3 messages" in err


def test_a_live_run_in_which_no_station_saw_the_object_says_what_to_change(
        tmp_path, monkeypatch, capsys):
    """A truth but not one measurement (a seed's case whose passes all fall after a short
    --duration): exit 1 with what to change, not "no /ssa/withheld messages"."""
    from ssa_fusion.apps import evaluate
    from ssa_fusion.core.base.types import StateEstimate

    truth = [StateEstimate(60.0 * k, np.zeros(6)) for k in range(3)]
    monkeypatch.setattr(runs, "run_graph", _FakeGraph)
    monkeypatch.setattr(evaluate, "load", lambda _bag: evaluate.BagData(
        counts={"/clock": 3, "/ssa/truth": 3}, truth=truth))
    args = cli.build_parser().parse_args(["live", "--scenario", "iss_radar_columbus",
                                          "--duration", "4", "--out", str(tmp_path / "run")])
    assert live.run(args) == 1
    err = capsys.readouterr().err
    assert ("error: the run cannot be evaluated: no station saw the object in the run's 4 h "
            "(0 measurements): a longer --duration, another --seed") in err, err


def test_a_live_run_whose_outage_withheld_nothing_is_judged_against_its_truth(
        tmp_path, monkeypatch, capsys):
    """No pass fell in the outage (a short run, one's own sites): no arms to score, so the
    run is judged as one's own data is (residuals, NIS, sigma, passes), exit 0 (it was an
    error, exit 1), and against the truth the bag holds (it printed "no simulated truth" and
    report.json said ``"truth": false``)."""
    from ssa_fusion.apps import evaluate

    data = evaluate.load(Path(SAMPLE))
    data.withheld = []
    monkeypatch.setattr(runs, "run_graph", _FakeGraph)
    monkeypatch.setattr(evaluate, "load", lambda _bag: data)
    out = tmp_path / "run"
    args = cli.build_parser().parse_args(["live", "--out", str(out)])
    assert live.run(args) == 0
    text = capsys.readouterr().out
    assert "no pass fell in the run's outage" in text
    assert "NIS inside the 95 % χ² band" in text
    assert f"judged against its /ssa/truth ({len(data.truth)} states)" in text, text
    assert "after each pass: median error" in text, text
    assert (out / "report.html").exists() and (out / "nis.png").exists()
    saved = json.loads((out / "report.json").read_text())
    error = saved["position_error"]
    assert saved["truth"] is True and error["truth_states"] == len(data.truth)
    assert 0.0 < error["after_pass_median_km"] < 50.0, error  # the paper's Keplerian EKF
    assert "Position error against the truth" in (out / "report.html").read_text()


@pytest.mark.parametrize("option", [["--objects", "5"], ["--shards", "2"], ["--no-surrogate"],
                                    ["--surrogate-param", "min_span=1"], ["--synthetic", "3"]])
def test_catalog_options_without_a_catalog_are_refused(option, tmp_path, capsys):
    """They were silently ignored: the scenario ran as if they were not given."""
    args = cli.build_parser().parse_args(["live", "--out", str(tmp_path / "run"), *option])
    assert live.run(args) == 2
    assert f"error: {option[0]} apply to a catalog run (--catalog FILE)" in \
        capsys.readouterr().err
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM, signal.SIGHUP])
def test_a_stop_signal_runs_the_commands_cleanup_and_exits_128_plus_its_number(
        sig, monkeypatch, capsys):
    """In process: the command's `finally` (a live run's: stop every node, close the bag)
    runs, a second signal during it is ignored, the exit code is a shell's. (A real `live`
    stopped by SIGTERM: test/graph/test_live_signals.py.)"""
    cleaned = []

    def command(_args) -> int:
        try:
            os.kill(os.getpid(), sig)
            time.sleep(5.0)  # the signal interrupts this
            return 0
        finally:
            os.kill(os.getpid(), sig)  # a second one must not cut the cleanup short
            cleaned.append(True)

    class Parser:  # a command line that runs `command`
        def __init__(self, _only: str | None = None) -> None:
            pass

        def parse_args(self, _argv) -> argparse.Namespace:
            return argparse.Namespace(command="report", _run=command)

    monkeypatch.setattr(cli, "build_parser", Parser)
    before = signal.getsignal(sig)
    assert cli.main(["report", "bag"]) == 128 + sig
    assert cleaned == [True]
    assert f"stopped by {signal.Signals(sig).name}" in capsys.readouterr().err
    assert signal.getsignal(sig) == before  # the handlers are put back


def test_a_stop_signal_that_a_c_extension_turned_into_its_own_error_still_stops_cleanly(
        monkeypatch, capsys):
    """The signal's exception raised inside rclpy's taking a message comes out as pybind11's
    RuntimeError ("Unable to convert call argument ..."): still a stop, exit 143; the same
    error without a signal is an error."""
    def command(_args) -> int:
        try:
            os.kill(os.getpid(), signal.SIGTERM)
            time.sleep(5.0)
            return 0
        except BaseException:  # as pybind11 does with an exception in a conversion
            raise RuntimeError("Unable to convert call argument '0' to Python object") from None

    def broken(_args) -> int:
        raise RuntimeError("Unable to convert call argument '0' to Python object")

    for run in (command, broken):
        parser = type("Parser", (), {
            "__init__": lambda self, _only=None: None,
            "parse_args": lambda self, _argv, run=run: argparse.Namespace(command="report",
                                                                          _run=run)})
        monkeypatch.setattr(cli, "build_parser", parser)
        if run is command:
            assert cli.main(["report", "bag"]) == 128 + signal.SIGTERM
            assert "stopped by SIGTERM" in capsys.readouterr().err
        else:
            with pytest.raises(RuntimeError, match="Unable to convert"):
                cli.main(["report", "bag"])


@pytest.mark.filterwarnings("ignore::pytest.PytestUnraisableExceptionWarning")
def test_a_stop_signal_whose_exception_python_ignored_during_the_imports_still_stops(
        monkeypatch, capsys):
    """A SIGTERM that lands in importlib's module-lock callback, where Python prints its
    exception ("Exception ignored in ...") and goes on: the command does not start, exit 143
    (it ran the whole graph before)."""
    ran = []

    def parser_whose_imports_swallow_the_signal(_only=None):
        class Parser:
            def parse_args(self, _argv):
                class Module:
                    pass
                module = Module()
                ref = weakref.ref(module, lambda _r: os.kill(os.getpid(), signal.SIGTERM))
                del module  # the callback runs here; its exception is ignored
                assert ref() is None
                return argparse.Namespace(command="live", _run=lambda _a: ran.append(1) or 0)
        return Parser()

    monkeypatch.setattr(cli, "build_parser", parser_whose_imports_swallow_the_signal)
    assert cli.main(["live"]) == 128 + signal.SIGTERM
    assert not ran
    assert "stopped by SIGTERM" in capsys.readouterr().err


def _catches(pid: int, sig: int) -> bool:
    """Whether process `pid` has a handler for `sig` (/proc/PID/status SigCgt)."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("SigCgt:"):
            return bool(int(line.split()[1], 16) >> (sig - 1) & 1)
    return False


def test_a_sigterm_while_the_command_still_imports_ends_it_cleanly(tmp_path):
    """The handlers are set before the commands' modules are imported (a second or two): a
    SIGTERM then gave rc -15 with no word; now 143 and the one line, as later."""
    import subprocess
    import sys

    exe = Path(sys.executable).parent / "ssa-fusion"
    p = subprocess.Popen([str(exe), "live", "--catalog", "config/catalogs/sample.tle",
                          "--out", str(tmp_path / "run")], cwd=Path(__file__).parents[2],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    # the moment the process catches SIGTERM (its SigCgt mask): the handlers are set and the
    # imports begin; before it, the interpreter itself is still starting (a signal then is
    # the kernel's default, as for any program), which a loaded machine stretches
    deadline = time.monotonic() + 30.0
    while time.monotonic() < deadline and not _catches(p.pid, signal.SIGTERM):
        time.sleep(0.001)
    p.send_signal(signal.SIGTERM)
    out, err = p.communicate(timeout=60)
    assert p.returncode == 143, (out, err)
    assert "stopped by SIGTERM" in err.splitlines()[-1] and "Traceback" not in err


@pytest.mark.parametrize(("argv", "error"), [
    (["--scenario", "iss_j2_pos", "--gap-forecast", "batch_fit"],
     "--gap-forecast applies to the real-sky scenarios"),
    (["--catalog", "config/catalogs/sample.tle", "--gap-forecast", "batch_fit"],
     "--surrogate-param gap_forecast=residual|batch_fit"),
])
def test_gap_forecast_is_a_real_sky_scenarios_option(argv, error, tmp_path, capsys):
    args = cli.build_parser().parse_args(["live", "--out", str(tmp_path / "run"), *argv])
    assert live.run(args) == 2
    assert error in capsys.readouterr().err
    assert not (tmp_path / "run").exists()


def test_gap_forecast_sets_the_filters_gap_forecast(monkeypatch, tmp_path):
    """The filter node starts with the option's `gap_forecast`, not the scenario's."""
    started = {}

    class StoppedError(Exception):
        pass

    class Graph(_FakeGraph):
        def start_node(self, name, params=None, **_kw):
            started[name] = params
            if name == "sensor_sim":
                raise StoppedError
            return object()

    monkeypatch.setattr(runs, "run_graph", Graph)
    for option, want in (([], "batch_init"), (["--gap-forecast", "residual"], "residual")):
        args = cli.build_parser().parse_args(["live", "--out", str(tmp_path / want),
                                              "--scenario", "iss_radar_columbus", *option])
        with pytest.raises(StoppedError):
            live.run(args)
        assert started["filter"]["gap_forecast"] == want
