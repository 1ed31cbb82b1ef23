#!/bin/sh
# make demo, the part on the bus (in the VM, or directly where the host has
# vcan): kleeman-lab live through simulator -> vcan0 -> bridge -> MAVLink.
# The live view goes to $BL_RESULTS/live.txt (the host shows it as it grows).
#   demo.sh [SECONDS]     length of the live run (default 120, the scenario's)
set -u
: "${BL_RESULTS:?run me through tests/vm/run-in-vm.sh}"
cd "$(dirname "$0")/../.."
exec env PYTHONDONTWRITEBYTECODE=1 .venv/bin/python tests/demo/demo.py \
    --out "$BL_RESULTS" --duration "${1:-120}"
