#!/usr/bin/env bash
# Run the test suite (`make test`): the graph tests (test/graph: real node processes over
# DDS) and the rest side by side, each group in a network namespace of its own
# (tools/isolated.sh), so the two cannot hear each other's DDS traffic whatever
# ROS_DOMAIN_ID their graphs pick. Most of a graph test's time is spent
# waiting on node processes, so the two groups share 2 cores well. Where no namespace can be
# made (not root, no iproute2, or SSA_FUSION_NO_NETNS=1) both groups would share the
# machine's loopback, and the suite runs as one pytest instead.
#
# Usage: tools/run_tests.sh [pytest options ...]   (options, not paths: given to both groups)
# Exit status: 0 when both groups pass, else the first non-zero of (rest, graph).
set -uo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
PY=.venv/bin/python

probe="ssa_fusion_probe_$$"
if [[ "${SSA_FUSION_NO_NETNS:-}" == "1" ]] || ! command -v ip >/dev/null 2>&1 ||
   ! ip netns add "$probe" 2>/dev/null; then
  exec tools/isolated.sh "$PY" -m pytest "$@"
fi
ip netns del "$probe"

# SSA_TEST_WORKERS=N runs each group on N pytest-xdist workers, a test file at a time per
# worker (default 0: one process per group). With 2, four workers keep 2 cores busy (a fresh
# clone 10-11 min instead of ~12.5), but graph tests that wait on DDS discovery (a run's
# 2 s domain probe) failed under that load in 2 of 5 runs. Workers of one namespace pick
# their ROS domains from parts of their own (test/conftest.py).
XDIST=(-n "${SSA_TEST_WORKERS:-0}" --dist loadfile)
log=$(mktemp -d)
trap 'rm -rf "$log"' EXIT
# The graphs' group writes to a log, printed when it ends; the rest shows its progress live.
# Three graph test files run in the rest's group, so that the groups take about as long
# (on an idle 2-core machine the graph tests took ~370 s and the rest ~240 s side by side).
IN_REST=(test/graph/test_live_signals.py test/graph/test_multihost_graph.py
         test/graph/test_unlabelled_graph.py)
GRAPHS=(test/graph/test_faults.py)
for f in test/graph/test_*.py; do
  [[ "$f" == test/graph/test_faults.py ]] && continue
  [[ " ${IN_REST[*]} " == *" $f "* ]] || GRAPHS+=("$f")
done
setsid tools/isolated.sh "$PY" -m pytest -p no:cacheprovider "${XDIST[@]}" "$@" "${GRAPHS[@]}" \
  >"$log/graph" 2>&1 &
graph=$!
# its own process group (setsid): a Ctrl-C here reaches it through this trap
trap 'kill -INT -- "-$graph" 2>/dev/null; wait "$graph"; rm -rf "$log"; exit 130' INT TERM
echo "run_tests: test/graph (but ${IN_REST[*]}) runs beside the rest (its output follows the rest's)"
tools/isolated.sh "$PY" -m pytest "${XDIST[@]}" "$@" "${GRAPHS[@]/#/--ignore=}" test
rest=$?
wait "$graph"
graph_rc=$?
echo
echo "run_tests: test/graph (but ${IN_REST[*]})"
cat "$log/graph"
if ((rest != 0)); then exit "$rest"; fi
exit "$graph_rc"
