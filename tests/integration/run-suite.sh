#!/bin/sh
# The integration suite on the bus that tests/vm/guest-init.sh brought up.
# Everything it writes goes to $BL_RESULTS (the repository may be read-only).
#   run-suite.sh [PYTEST ARGS...]     e.g. -k nominal
set -u
: "${BL_RESULTS:?run me through tests/vm/run-in-vm.sh}"
cd "$(dirname "$0")/../.."
exec env PYTHONDONTWRITEBYTECODE=1 .venv/bin/python -m pytest tests/integration \
    -c tests/integration/pytest.ini -p no:cacheprovider \
    --junitxml="$BL_RESULTS/junit.xml" --basetemp="$BL_RESULTS/cases" \
    -v -ra --durations=0 "$@"
