#!/bin/sh
# The integration suite on the bus that tests/vm/guest-init.sh brought up.
# Everything it writes goes to $BL_RESULTS (the repository may be read-only).
#   run-suite.sh [PYTEST ARGS...]     e.g. -k nominal
# The live cases run side by side (pytest-xdist, one worker each, every case
# on its own vcan interfaces and UDP port): BL_IT_WORKERS workers (default 11,
# the number of independent live runs; 0 runs them one after another).
set -u
: "${BL_RESULTS:?run me through tests/vm/run-in-vm.sh}"
cd "$(dirname "$0")/../.."
exec env PYTHONDONTWRITEBYTECODE=1 .venv/bin/python -m pytest tests/integration \
    -c tests/integration/pytest.ini -p no:cacheprovider \
    --junitxml="$BL_RESULTS/junit.xml" --basetemp="$BL_RESULTS/cases" \
    -n "${BL_IT_WORKERS:-11}" \
    -v -ra --durations=0 "$@"
