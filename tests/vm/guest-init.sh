#!/bin/sh
# beaconloc: runs inside the User-Mode Linux guest (tests/vm/uml-init.sh
# starts it) or directly on a host that has vcan. Brings up the kernel CAN
# bus, proves it with a python-can round trip, then runs the given command
# with the results folder in $BL_RESULTS.
#
#   guest-init.sh RESULTS_DIR COMMAND [ARGS...]
#
# Writes into RESULTS_DIR: booted (first thing, so the host can tell a boot
# failure from a test failure), bus.log (modprobe/ip/round-trip output),
# script.log (the command's stdout+stderr), exit-code (the command's status,
# or 90 when the bus could not be brought up).
# Nothing here writes into the repository: only RESULTS_DIR.
set -u
RESULTS=$1
shift
mkdir -p "$RESULTS"
echo "kernel $(uname -r) $(date -u +%FT%TZ)" > "$RESULTS/booted"

export PYTHONDONTWRITEBYTECODE=1
# BL_SCRATCH: a folder for files written during the run (uml-init.sh gives a
# tmpfs in the guest's memory; elsewhere a fresh temporary folder).
if [ -z "${BL_SCRATCH:-}" ]; then BL_SCRATCH=$(mktemp -d); fi
export BL_SCRATCH
export HOME=${BL_GUEST_HOME:-$BL_SCRATCH/home}
export MPLCONFIGDIR=$HOME/mpl
export MPLBACKEND=Agg
export BL_RESULTS=$RESULTS
mkdir -p "$HOME" "$MPLCONFIGDIR"
REPO=$(cd "$(dirname "$0")/../.." && pwd)
export PATH="$REPO/.venv/bin:$PATH"

bus_ok=1
{
  echo "# bus set-up on $(uname -r)"
  # Modules, in dependency order (vcan needs can-dev; can-gw joins two buses
  # in the interface-down case). Already loaded or built in: nothing to do.
  # modprobe where the kernel's tree is in /lib/modules; the UML kernel keeps
  # its modules in /usr/lib/uml/modules/VER (Debian's user-mode-linux).
  uml_mods=/usr/lib/uml/modules/$(uname -r)/kernel
  for m in can can_raw can_dev vcan can_gw; do
    [ -d "/sys/module/$m" ] && continue
    modprobe "$m" 2>/dev/null && continue
    ko=$(find "$uml_mods" -name "$(echo "$m" | tr _ -).ko" 2>/dev/null | head -n 1)
    if [ -n "$ko" ] && insmod "$ko"; then echo "loaded $ko"; continue; fi
    echo "cannot load module $m"
  done
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
