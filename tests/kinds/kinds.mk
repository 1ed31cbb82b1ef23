# tests/kinds: issue 10's claim, end to end: a new sensor kind (a compass, kept as
# fixtures in tests/kinds/compass/) is six files and nothing else is edited. The test
# copies the tracked tree into a temporary directory, adds the kind, checks the six
# paths, builds the bridge there from nothing (about a minute of one build at nice 19),
# simulates 30 s of kleeman-lab with a compass and replays it (tests/kinds/test_new_kind.py).
#   make test-kinds
.PHONY: test-kinds

PY_TESTS += test-kinds

test-kinds: | $(SETUP_STAMP)
	$(PYTEST) -q -p no:cacheprovider tests/kinds
