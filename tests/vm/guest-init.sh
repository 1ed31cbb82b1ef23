#!/bin/sh
# beaconloc: runs inside the virtme-ng guest (or directly on a host that has
# vcan). Brings up the kernel CAN bus, proves it with a python-can round trip,
# then runs the given command with the results folder in $BL_RESULTS.
#
#   guest-init.sh RESULTS_DIR COMMAND [ARGS...]
#
# Writes into RESULTS_DIR: booted (first thing, so the host can tell a boot
# failure from a test failure), bus.log (modprobe/ip/round-trip output),
# script.log (the command's stdout+stderr), exit-code (the command's status,
# or 90 when the bus could not be brought up).
# The repository is read-only inside the guest: nothing here writes into it.
set -u
RESULTS=$1
shift
mkdir -p "$RESULTS"
echo "kernel $(uname -r) $(date -u +%FT%TZ)" > "$RESULTS/booted"

export PYTHONDONTWRITEBYTECODE=1
export HOME=${BL_GUEST_HOME:-/tmp/bl-home}
export MPLCONFIGDIR=$HOME/mpl
export MPLBACKEND=Agg
export BL_RESULTS=$RESULTS
mkdir -p "$HOME" "$MPLCONFIGDIR"
REPO=$(cd "$(dirname "$0")/../.." && pwd)
export PATH="$REPO/.venv/bin:$PATH"

bus_ok=1
{
  echo "# bus set-up on $(uname -r)"
  # Modules: a no-op where they are built in or already loaded.
  modprobe vcan 2>&1 || echo "modprobe vcan failed (built in?)"
  modprobe can-raw 2>&1 || echo "modprobe can-raw failed (built in?)"
  for ifc in ${BL_VCAN_IFACES:-vcan0}; do
    if ! ip link show "$ifc" >/dev/null 2>&1; then
      ip link add dev "$ifc" type vcan || { echo "cannot create $ifc"; bus_ok=0; }
    fi
    ip link set up "$ifc" || { echo "cannot bring up $ifc"; bus_ok=0; }
    ip -details link show "$ifc"
  done
  # The riskiest link of the chain first: one frame out and back on vcan0.
  "$REPO/.venv/bin/python" "$REPO/tests/vm/vcan_roundtrip.py" vcan0 || bus_ok=0
} > "$RESULTS/bus.log" 2>&1

if [ "$bus_ok" -ne 1 ]; then
  echo "bus set-up failed, see bus.log" > "$RESULTS/script.log"
  echo 90 > "$RESULTS/exit-code"
  exit 90
fi

cd "$REPO"
"$@" > "$RESULTS/script.log" 2>&1
rc=$?
echo "$rc" > "$RESULTS/exit-code"
exit "$rc"
