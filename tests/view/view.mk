# tests/view: beaconloc-view (hw_sim/beaconloc_sim/view/, docs/view.md), the live map.
#   make test-view   pytest tests/view/: the state model on encoded MAVLink, and the page in
#                    headless Chromium during a paced bridge replay (screenshot in the test's
#                    tmp folder)
#   make fig-view    docs/img/view.png: the page after a paced replay of beacon-outage
.PHONY: test-view fig-view

PY_TESTS += test-view

test-view: $(BRIDGE_BIN) | $(SETUP_STAMP)
	BL_BUILD=$(abspath $(BUILD)) $(PYTEST) -q -p no:cacheprovider tests/view

fig-view: $(BRIDGE_BIN) | $(SETUP_STAMP)
	mkdir -p docs/img
	BL_BUILD=$(abspath $(BUILD)) $(PY) tests/view/fig_view.py --out docs/img/view.png
