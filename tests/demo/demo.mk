# make demo's live map (tests/demo/view.sh, docs/view.md): beaconloc-view on the host,
# started before the live run (the demo rule itself is in tests/integration/integration.mk),
# following the MAVLink frames the guest writes into the demo's results folder.
#   make demo [DEMO_VIEW_PORT=8765] [DEMO_VIEW_LINGER=120]
DEMO_VIEW_PORT   ?= 8765
DEMO_VIEW_LINGER ?= 120
.PHONY: demo-view

demo: demo-view
demo-view: | $(SETUP_STAMP)
	@sh tests/demo/view.sh $(BUILD)/demo $(DEMO_VIEW_PORT) $(DEMO_VIEW_LINGER)
