# hw_sim: the Python hardware simulator (package beaconloc_sim, console beaconloc-sim).
#   make test-sim    pytest tests/sim/ (physics vs closed forms, DBC round trip, CRB, CLI)
#   make bench-sim   120 s kleeman-lab log write time + live pacing on python-can's virtual bus;
#                    last line: bench-sim ... (machine-readable key=value)
#   make fig-vander5 Vander 2011 Fig. 5: the drms map of triangulation (sigma_phi = 1 deg) on the
#                    Eurobot table -> docs/img/vander-fig5.png, with the figures of each half
#                    (halves ... line) and the map line; FIG_SITE=path for another site file
.PHONY: test-sim bench-sim fig-vander5

PY_TESTS += test-sim

test-sim: | $(SETUP_STAMP)
	$(PYTEST) -q -p no:cacheprovider tests/sim

bench-sim: | $(SETUP_STAMP)
	$(PY) tests/sim/bench_sim.py

# the eurobot site when it is there, else the test copy of Vander's table (same numbers)
FIG_SITE ?= $(firstword $(wildcard hw_sim/beaconloc_sim/data/scenarios/eurobot.ini) \
                        tests/sim/vander-table.ini)
fig-vander5: | $(SETUP_STAMP)
	mkdir -p docs/img
	$(VENV)/bin/beaconloc-sim map $(FIG_SITE) --kind bearing --halves --step 0.01 \
	    --out docs/img/vander-fig5.png
