# End to end on a kernel CAN bus (tests/integration, tests/vm, tests/bench,
# tests/demo). The bus lives in a virtme-ng VM where the host has no vcan.
#   make test-integration [IT_ARGS='-k nominal']   the pytest suite, one VM boot
#   make bench-accuracy                            20 seeds x 2 scenarios, --replay
#   make demo                                      kleeman-lab live, plot in build/demo/
#   make vm-check                                  boot, python-can round trip on vcan0

IT_RESULTS   := $(BUILD)/vm
DEMO_OUT     := $(BUILD)/demo
IT_BRIDGE    := $(BUILD)/bridge/beaconloc-bridge
VM_RUN       := tests/vm/run-in-vm.sh
IT_ARGS      ?=

.PHONY: test-integration bench-accuracy demo vm-check

test-integration: $(SETUP_STAMP) $(IT_BRIDGE)
	$(VM_RUN) --results $(IT_RESULTS) --junit junit.xml \
	    tests/integration/run-suite.sh $(IT_ARGS)

vm-check: $(SETUP_STAMP)
	$(VM_RUN) --results $(BUILD)/vm-check true

bench-accuracy: $(SETUP_STAMP) $(IT_BRIDGE)
	$(PY) tests/bench/accuracy.py --bridge $(IT_BRIDGE) --out $(BUILD)/bench/accuracy

demo: $(SETUP_STAMP) $(IT_BRIDGE)
	$(VM_RUN) --results $(DEMO_OUT) --tail live.txt tests/demo/demo.sh
	$(PY) tests/demo/summary.py $(DEMO_OUT)
