# make readme-img — the README's pictures, regenerated (never drawn by hand):
#   docs/img/demo-kleeman-lab.png  the demo's plot (path, error vs its 3 sigma and the
#                                  Cramer-Rao bound, speed of sound) of kleeman-lab seed 1,
#                                  through the simulator's log and the real bridge in --replay
#                                  (make demo draws the same plot from its live run)
#   docs/img/map-kleeman-lab.png   the site planner's map of the ultrasonic site
#   docs/img/map-marvelmind.png    ... and of the fixed range beacons (Marvelmind-like)
.PHONY: readme-img
README_IMG_TMP := $(BUILD)/readme-img
SCEN_DIR       := hw_sim/beaconloc_sim/data/scenarios

readme-img: $(BRIDGE_BIN) | $(SETUP_STAMP)
	@mkdir -p $(README_IMG_TMP) docs/img
	$(VENV)/bin/beaconloc-sim run kleeman-lab --seed 1 --log $(README_IMG_TMP)/k.log \
	    --truth $(README_IMG_TMP)/truth.csv --odometry $(README_IMG_TMP)/odometry.csv
	$(BRIDGE_BIN) --site $(SCEN_DIR)/kleeman-lab.ini --replay $(README_IMG_TMP)/k.log \
	    --estimates $(README_IMG_TMP)/est.csv
	$(VENV)/bin/beaconloc-sim plot --truth $(README_IMG_TMP)/truth.csv \
	    --estimates $(README_IMG_TMP)/est.csv --odometry $(README_IMG_TMP)/odometry.csv \
	    --out docs/img/demo-kleeman-lab.png
	$(VENV)/bin/beaconloc-sim map kleeman-lab --out docs/img/map-kleeman-lab.png
	$(VENV)/bin/beaconloc-sim map $(SCEN_DIR)/marvelmind.ini --out docs/img/map-marvelmind.png
