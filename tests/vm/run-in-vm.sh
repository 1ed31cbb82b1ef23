#!/bin/sh
# Run COMMAND on a real kernel CAN bus (vcan0): directly where the host has
# vcan, else in one virtme-ng VM. See tests/vm/run_in_vm.py --help.
#   tests/vm/run-in-vm.sh [--results DIR] [--junit FILE] [--tail FILE] COMMAND [ARGS...]
set -e
here=$(cd "$(dirname "$0")" && pwd)
repo=$(cd "$here/../.." && pwd)
py="$repo/.venv/bin/python"
[ -x "$py" ] || { echo "run-in-vm: $py missing: run 'make setup'" >&2; exit 2; }
exec "$py" "$here/run_in_vm.py" "$@"
