#!/usr/bin/env bash
# Run a command in a network namespace of its own (loopback only), when this machine lets us
# make one (root and iproute2); otherwise run it as it is, saying so.
#
# The test suite's graphs talk DDS over loopback. Inside a fresh namespace the loopback is
# the run's own, so no other ROS graph on the machine (another test run, a user's graph) can
# discover its nodes or be discovered, whatever ROS_DOMAIN_ID either picks.
set -uo pipefail
NS="ssa_fusion_test_$$"
if [[ "${SSA_FUSION_NO_NETNS:-}" != "1" ]] && command -v ip >/dev/null 2>&1 &&
   ip netns add "$NS" 2>/dev/null; then
  trap 'ip netns del "$NS" 2>/dev/null' EXIT INT TERM
  ip netns exec "$NS" ip link set lo up
  echo "isolated: running in network namespace $NS (its own loopback)" >&2
  ip netns exec "$NS" "$@"
  exit $?
fi
echo "isolated: no network namespace (not root, no iproute2, or SSA_FUSION_NO_NETNS=1);" \
     "running on the machine's loopback" >&2
exec "$@"
