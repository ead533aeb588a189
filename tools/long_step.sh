# Sourced by tools/bootstrap.sh: run a long command with a line on stderr at least every
# BOOTSTRAP_TICK_S seconds (default 5), so that a step of minutes (pip, a CMake build) never
# looks like a hang. Each line says the step, the seconds it has run and the command's latest
# line of progress (pip's "Collecting ...", "Installing collected packages", a build's
# "[ 40%] ..."). The command's whole output goes to a log; on failure its last 40 lines are
# shown and the command's exit code returned.
#
#   long_step LOG LABEL COMMAND [ARG...]

BOOTSTRAP_TICK_S="${BOOTSTRAP_TICK_S:-5}"

# The latest line of LOG that says how far a step has got (pip and CMake words), else "".
latest_progress() {
  grep -E '^(Collecting|Downloading|Processing|Obtaining|Building|Installing|Successfully|Requirement|Preparing|Using cached|\[ *[0-9]+%\]|-- (Build files|Configuring done|Generating done)|Install the project)' \
    "$1" 2>/dev/null | tail -n 1 | cut -c1-110 || true
}

long_step() {
  local log="$1" label="$2"
  shift 2
  mkdir -p "$(dirname "$log")"
  : >"$log"
  local start=$SECONDS
  "$@" >>"$log" 2>&1 &
  local pid=$!
  local waited=0 said=0
  while kill -0 "$pid" 2>/dev/null; do
    sleep 0.2
    waited=$((waited + 1))
    # 0.2 s sleeps: the tick in fifths of a second
    if ((waited * 2 >= BOOTSTRAP_TICK_S * 10)); then
      waited=0 said=1
      local now
      now=$(latest_progress "$log")
      echo "bootstrap:   ${label}: $((SECONDS - start)) s${now:+ ... $now}" >&2
    fi
  done
  local code=0
  wait "$pid" || code=$?
  if ((code != 0)); then
    tail -n 40 "$log" >&2
    return "$code"
  fi
  if ((said)); then echo "bootstrap:   ${label}: done in $((SECONDS - start)) s" >&2; fi
}
