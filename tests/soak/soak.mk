# Soak (tests/soak): hours of simulated kleeman-lab time, one fault an hour, through
# the real bridge in --replay (docs/soak.md).
#   make soak [SOAK_H=24]   simulate, replay, judge; per-hour table, targets, last line
#                           soak sim_h=.. frames=.. rss_growth_kib=.. nan=.. resets=.. ...
#   make test-soak          pytest: a 2-hour soak (line format and targets), in make test-py

SOAK_H   ?= 24
SOAK_OUT := $(BUILD)/soak

.PHONY: soak test-soak

PY_TESTS += test-soak

soak: $(SETUP_STAMP) $(BRIDGE_BIN)
	SOAK_H=$(SOAK_H) $(PY) tests/soak/soak.py --bridge $(BRIDGE_BIN) --out $(SOAK_OUT)

test-soak: $(SETUP_STAMP) $(BRIDGE_BIN)
	BL_BUILD=$(abspath $(BUILD)) PYTHONDONTWRITEBYTECODE=1 $(PYTEST) -q -p no:cacheprovider \
	    tests/soak
