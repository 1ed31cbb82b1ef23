# lib/bench.mk — make bench-speed: ns per pulse fusion / predict (double and
# float), callgrind instructions per fusion, FilterPy's EKF update as the
# reference, ns per bearing triangulation (3 beacons closed form, 4 beacons
# least squares), in one run (lib/bench/run_speed.py). Last line:
#   speed fuse_pulse_ns=<n> predict_ns=<n> fuse_pulse_instr=<n> filterpy_ratio=<r> triangulate3_ns=<n> triangulateN_ns=<n>

BENCH_DIR    := $(BUILD)/bench
BENCH_CFLAGS := -std=c11 -O2 -Wall -Wextra -Werror $(LIB_INCLUDES)
BENCH_HDRS   := $(wildcard lib/include/*.h lib/include/beaconloc/*.h) $(LIB_KINDS_H)

$(BENCH_DIR)/bench_speed_double: lib/bench/bench_speed.c $(BUILD)/lib/libbeaconloc.a $(BENCH_HDRS)
	@mkdir -p $(@D)
	$(CC) $(BENCH_CFLAGS) $< $(BUILD)/lib/libbeaconloc.a -lm -o $@

$(BENCH_DIR)/bench_speed_float: lib/bench/bench_speed.c $(BUILD)/lib/float/libbeaconloc.a $(BENCH_HDRS)
	@mkdir -p $(@D)
	$(CC) $(BENCH_CFLAGS) -DBL_USE_FLOAT=1 $< $(BUILD)/lib/float/libbeaconloc.a -lm -o $@

bench-speed: $(BENCH_DIR)/bench_speed_double $(BENCH_DIR)/bench_speed_float | $(SETUP_STAMP)
	$(PY) lib/bench/run_speed.py --double $(BENCH_DIR)/bench_speed_double \
	    --float $(BENCH_DIR)/bench_speed_float --out-dir $(BENCH_DIR) --python $(PY)

# make bench-sequencer: numbering accuracy of the sequencer on every hw_sim
# scenario's detections against the simulator's ground truth
# (lib/bench/bench_sequencer.py). Last line:
#   sequencer scenarios=<n> seeds=<n> direct=<n> numbered_pct=<%> wrong_direct=<n> wrong_echo=<n> spurious=<n> unlocked=<n>
.PHONY: bench-sequencer
$(BENCH_DIR)/seq_replay: lib/bench/seq_replay.c $(BUILD)/lib/libbeaconloc.a $(BENCH_HDRS)
	@mkdir -p $(@D)
	$(CC) $(BENCH_CFLAGS) $< $(BUILD)/lib/libbeaconloc.a -lm -o $@

bench-sequencer: $(BENCH_DIR)/seq_replay | $(SETUP_STAMP)
	$(PY) lib/bench/bench_sequencer.py --replay $(BENCH_DIR)/seq_replay

# The bearing triangulation on a stream of scans, for make bench-bearing
# (tests/bench/bearing.py, tests/integration/integration.mk).
$(BENCH_DIR)/triangulate: lib/bench/triangulate.c $(BUILD)/lib/libbeaconloc.a $(BENCH_HDRS)
	@mkdir -p $(@D)
	$(CC) $(BENCH_CFLAGS) $< $(BUILD)/lib/libbeaconloc.a -lm -o $@

# make bench-sonar-lib: us per correction of the sonar ring's pin-point and
# memory correctors and per burst fused by the filter (lib/bench/bench_sonar.c,
# the room of tests/lib/sonar_world.h), float then double. Last line (double):
#   bench_sonar real=double pinpoint_us=<n> memory_us=<n> fuse_sonar_burst_us=<n> pinpoint_target_us=20 memory_target_us=200 pinpoint_improved_pct=<%>
# (make bench-sonar, tests/bench/sonar.mk, reproduces Table 1 through the bridge.)
.PHONY: bench-sonar-lib
$(BENCH_DIR)/bench_sonar_double: lib/bench/bench_sonar.c tests/lib/sonar_world.h $(BUILD)/lib/libbeaconloc.a $(BENCH_HDRS)
	@mkdir -p $(@D)
	$(CC) $(BENCH_CFLAGS) -Itests/lib $< $(BUILD)/lib/libbeaconloc.a -lm -o $@

$(BENCH_DIR)/bench_sonar_float: lib/bench/bench_sonar.c tests/lib/sonar_world.h $(BUILD)/lib/float/libbeaconloc.a $(BENCH_HDRS)
	@mkdir -p $(@D)
	$(CC) $(BENCH_CFLAGS) -Itests/lib -DBL_USE_FLOAT=1 $< $(BUILD)/lib/float/libbeaconloc.a -lm -o $@

bench-sonar-lib: $(BENCH_DIR)/bench_sonar_double $(BENCH_DIR)/bench_sonar_float
	$(BENCH_DIR)/bench_sonar_float
	$(BENCH_DIR)/bench_sonar_double
