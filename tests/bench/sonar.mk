# The sonar benchmark (issue 12, Hoppenot & Colle 1997 Table 1; tests/bench/sonar.py):
#   make bench-sonar   the real bridge in --replay on hoppenot-room and hoppenot-obstacle,
#                      each [sonar_ring] method (pinpoint, memory, filter) on the same logs,
#                      sweeping the asymmetric wheel-diameter degradation; Table 1 beside
#                      ours, the time per correction, a PNG of the paths; last line:
#                      sonar scenario=hoppenot-room pinpoint_pct=.. memory_pct=.. ...
#   SONAR_BENCH_ARGS   its options (e.g. --seeds 3 --step 0.5 --symmetric)
# Its own logic is tested by tests/bench/test_sonar_bench.py (make test-bench, team.mk).
.PHONY: bench-sonar
SONAR_BENCH_ARGS ?=

bench-sonar: $(SETUP_STAMP) $(BUILD)/bridge/beaconloc-bridge
	$(PY) tests/bench/sonar.py --bridge $(BUILD)/bridge/beaconloc-bridge --out $(BUILD)/bench/sonar $(SONAR_BENCH_ARGS)
