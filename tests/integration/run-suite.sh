#!/bin/sh
# The integration suite on the bus that tests/vm/guest-init.sh brought up.
# Everything it writes goes to $BL_RESULTS (the repository may be read-only).
#   run-suite.sh [PYTEST ARGS...]     e.g. -k nominal
# Live runs one after the other in a guest by default (BL_IT_WORKERS=0):
# side by side (pytest-xdist, BL_IT_WORKERS=N, one live run per worker, each
# on its own vcan interfaces and UDP port) they starved each other on the
# guest's one CPU. BL_IT_SHARD=I/N runs the share of guest I of N.
set -u
: "${BL_RESULTS:?run me through tests/vm/run-in-vm.sh}"
cd "$(dirname "$0")/../.."
# Each case writes its files (logs, CSVs, stats) under $BL_SCRATCH, in the
# guest's memory; they are copied to $BL_RESULTS/cases at the end.
cases=${BL_SCRATCH:-$BL_RESULTS}/cases
trap 'if [ "$cases" != "$BL_RESULTS/cases" ] && [ -d "$cases" ]; then cp -a "$cases" "$BL_RESULTS/"; fi' EXIT
env PYTHONDONTWRITEBYTECODE=1 .venv/bin/python -m pytest tests/integration \
    -c tests/integration/pytest.ini -p no:cacheprovider \
    --junitxml="$BL_RESULTS/junit.xml" --basetemp="$cases" \
    -n "${BL_IT_WORKERS:-0}" \
    -v -ra --durations=0 "$@"
rc=$?
exit $rc
