# The team benchmark (issue 13, CMU Millibots; tests/bench/team.py):
#   make bench-team   the real bridge in --replay on 20 seeds of marvelmind (fixed range
#                     beacons), team-static and team-leapfrog, runs side by side on the
#                     cores; last line: team scenario=team-leapfrog robots=4 seeds=20 ...
#   make test-bench   its judgement on estimates made from the truth plus known noise
#                     (tests/bench/test_team_bench.py), and the lost robot through the
#                     bridge in replay (tests/bench/test_team_replay.py); in make test-py
# (the bridge by its path: integration.mk, which names it IT_BRIDGE, is read after this)
.PHONY: bench-team test-bench

PY_TESTS += test-bench
test-bench: $(SETUP_STAMP) $(BUILD)/bridge/beaconloc-bridge
	PYTHONDONTWRITEBYTECODE=1 $(PYTEST) -q -p no:cacheprovider tests/bench

bench-team: $(SETUP_STAMP) $(BUILD)/bridge/beaconloc-bridge
	$(PY) tests/bench/team.py --bridge $(BUILD)/bridge/beaconloc-bridge --out $(BUILD)/bench/team
