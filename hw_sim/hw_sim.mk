# hw_sim: the Python hardware simulator (package beaconloc_sim, console beaconloc-sim).
#   make test-sim    pytest tests/sim/ (physics vs closed forms, DBC round trip, CRB, CLI)
#   make bench-sim   120 s kleeman-lab log write time + live pacing on python-can's virtual bus;
#                    last line: bench-sim ... (machine-readable key=value)
.PHONY: test-sim bench-sim

PY_TESTS += test-sim

test-sim: | $(SETUP_STAMP)
	$(PYTEST) -q -p no:cacheprovider tests/sim

bench-sim: | $(SETUP_STAMP)
	$(PY) tests/sim/bench_sim.py
