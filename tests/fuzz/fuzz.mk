# tests/fuzz — coverage-guided fuzzing with libFuzzer (clang, ASan + UBSan).
# One harness per input surface (docs/fuzzing.md):
#   fuzz_replay    candump-log lines of --replay (bridge/replay.c)
#   fuzz_frames    SocketCAN reads and decoded CAN frames into the estimator
#                  (bridge/can_in.c, frames.c, estimator.c, node_clock.c)
#   fuzz_site      the site file (bridge/config.c, [tuning] included) up to
#                  the estimator's init and a SIGHUP reconfigure
#   fuzz_mavlink   what udpin: and serial endpoints receive (bridge/mav_input.c)
#   fuzz_lib_api   the library API as a state machine (lib/include/beaconloc/*.h)
#
#   make fuzz [FUZZ_SECONDS=60]   build and run each harness FUZZ_SECONDS; one
#                                 summary line per harness; fails on any crash
#   make fuzz-smoke               each harness FUZZ_SMOKE_RUNS inputs from a fixed
#                                 seed on the committed corpus (in UNIT_TESTS)
#   make fuzz-build               the harnesses only ($(BUILD)/fuzz/fuzz_*)
#   make fuzz-msan                fuzz_lib_api under MemorySanitizer, FUZZ_SECONDS
#   make fuzz-seeds               regenerate the committed seed corpus from the
#                                 simulator (tests/fuzz/make_seeds.py)
#
# The committed corpus tests/fuzz/corpus/<name>/ is a read-only seed
# directory; what the fuzzer finds goes to $(BUILD)/fuzz/corpus/<name>/,
# crashes to $(BUILD)/fuzz/artifacts/<name>/. Reproduce one with
#   $(BUILD)/fuzz/fuzz_<name> $(BUILD)/fuzz/artifacts/<name>/crash-...
# Everything here is built with clang into $(BUILD)/fuzz (the gcc builds are
# untouched); the generated CAN codec and MAVLink headers are the ones of
# bridge/bridge.mk and bridge/mavlink.mk.

FUZZ_DIR      := $(BUILD)/fuzz
FUZZ_CC       ?= clang
FUZZ_CXX      ?= clang++
FUZZ_SECONDS  ?= 60
# The smoke run of `make test`: a fixed number of inputs per harness from a
# fixed seed on the committed seeds alone (run_fuzz.sh NAME:RUNS), so that
# it passes or fails by the code alone: about 5 s each here; the seconds
# only bound it on a starved machine. Finding new defects is `make fuzz`.
FUZZ_SMOKE_SECONDS ?= 60
FUZZ_SMOKE_RUNS ?= replay:80000 frames:600 site:30000 mavlink:60000 lib_api:500
FUZZ_NAMES    := replay frames site mavlink lib_api
FUZZ_BINS     := $(addprefix $(FUZZ_DIR)/fuzz_,$(FUZZ_NAMES))

# Instrumentation for coverage (fuzzer-no-link) and the sanitizers on every
# object; -fsanitize=fuzzer adds libFuzzer's main at the link.
FUZZ_SAN      := -fsanitize=fuzzer-no-link,address,undefined \
                 -fno-sanitize-recover=undefined -fno-omit-frame-pointer -g -O1
FUZZ_LDSAN    := -fsanitize=fuzzer,address,undefined -fno-sanitize-recover=undefined
# Library and bridge sources as their own fragments compile them, minus
# -Werror (clang's warnings differ from gcc's; the gcc builds enforce them).
FUZZ_LIB_CXXFLAGS := $(filter-out -Werror,$(LIB_CXXFLAGS)) # Eigen asserts on
FUZZ_BR_CFLAGS    := -std=c11 -Wall -Wextra -MMD -MP
FUZZ_HARN_CFLAGS  := -std=c11 -D_GNU_SOURCE -Wall -Wextra -Werror -MMD -MP -Itests/fuzz \
                     -DFUZZ_SITE='"$(CURDIR)/hw_sim/beaconloc_sim/data/scenarios/kleeman-lab.ini"' \
                     -DFUZZ_BEARING_SITE='"$(CURDIR)/hw_sim/beaconloc_sim/data/scenarios/eurobot.ini"' \
                     -DFUZZ_RANGE_SITE='"$(CURDIR)/hw_sim/beaconloc_sim/data/scenarios/marvelmind.ini"' \
                     -DFUZZ_THERMOMETER_SITE='"$(CURDIR)/hw_sim/beaconloc_sim/data/scenarios/kleeman-thermometer.ini"' \
                     -DFUZZ_TEAM_SITE='"$(CURDIR)/hw_sim/beaconloc_sim/data/scenarios/millibots-room.ini"' \
                     -DFUZZ_SONAR_SITE='"$(CURDIR)/hw_sim/beaconloc_sim/data/scenarios/hoppenot-room.ini"'

FUZZ_LIB_OBJS := $(patsubst lib/src/%.cpp,$(FUZZ_DIR)/obj/lib/%.o,$(LIB_SRCS))
FUZZ_BR_OBJS  := $(patsubst bridge/%.c,$(FUZZ_DIR)/obj/bridge/%.o,$(filter-out bridge/main.c,$(BRIDGE_SRCS))) \
                 $(BRIDGE_GEN_NAMES:%=$(FUZZ_DIR)/obj/bridge/%.o)

.PHONY: fuzz fuzz-smoke fuzz-build fuzz-seeds fuzz-msan
UNIT_TESTS += fuzz-smoke
TEST_BUILDS += fuzz-build

$(FUZZ_DIR)/obj/lib/%.o: lib/src/%.cpp $(LIB_HDRS) tests/fuzz/fuzz.mk
	@mkdir -p $(@D)
	$(FUZZ_CXX) $(FUZZ_LIB_CXXFLAGS) $(FUZZ_SAN) -c $< -o $@

$(FUZZ_DIR)/obj/bridge/%.o: bridge/%.c $(BRIDGE_CAN_H) $(BRIDGE_MAVSTAMP) tests/fuzz/fuzz.mk
	@mkdir -p $(@D)
	$(FUZZ_CC) $(BRIDGE_CPPFLAGS) $(FUZZ_BR_CFLAGS) $(FUZZ_SAN) -c -o $@ $<

$(BRIDGE_GEN_NAMES:%=$(FUZZ_DIR)/obj/bridge/%.o): $(FUZZ_DIR)/obj/bridge/%.o: $(BRIDGE_CANGEN)/%.c \
        $(BRIDGE_CAN_H) $(BRIDGE_MAVSTAMP) tests/fuzz/fuzz.mk
	@mkdir -p $(@D)
	$(FUZZ_CC) $(BRIDGE_CPPFLAGS) $(FUZZ_BR_CFLAGS) $(FUZZ_SAN) -c -o $@ $<

$(FUZZ_DIR)/obj/fuzz_%.o: tests/fuzz/fuzz_%.c tests/fuzz/fuzz_common.h $(BRIDGE_CAN_H) $(BRIDGE_MAVSTAMP) tests/fuzz/fuzz.mk
	@mkdir -p $(@D)
	$(FUZZ_CC) $(BRIDGE_CPPFLAGS) $(FUZZ_HARN_CFLAGS) $(FUZZ_SAN) -c -o $@ $<

# The bridge's objects and the harnesses include the library's headers: its
# generated kinds' list first (lib/lib.mk; the lib objects have it in LIB_HDRS).
$(FUZZ_BR_OBJS) $(FUZZ_NAMES:%=$(FUZZ_DIR)/obj/fuzz_%.o): | $(LIB_KINDS_H)

# Every harness links the whole bridge (all but main.o) and the library; the
# linker keeps what it calls. fuzz_frames stands in for recvmsg (the CAN
# socket's read) with its own function, as tests/bridge/test_can_in.c does,
# and for clock_gettime with a clock that moves by the input alone.
FUZZ_LDFLAGS_frames := -Wl,--wrap=recvmsg -Wl,--wrap=clock_gettime

$(FUZZ_DIR)/fuzz_%: $(FUZZ_DIR)/obj/fuzz_%.o $(FUZZ_BR_OBJS) $(FUZZ_LIB_OBJS)
	$(FUZZ_CXX) $(FUZZ_LDSAN) -o $@ $< $(FUZZ_BR_OBJS) $(FUZZ_LIB_OBJS) \
	    $(FUZZ_LDFLAGS_$*) -linih -lm

# Dictionary of the site-file harness: every section and key of the site
# schema (derived, not copied), plus INI syntax and values.
$(FUZZ_DIR)/site.dict: $(SITE_SCHEMA) $(SITE_SCHEMA_PY) tests/fuzz/site_syntax.dict | $(SETUP_STAMP)
	@mkdir -p $(@D)
	$(PY) -m beaconloc_sim.site_schema fuzz-dict > $@.tmp
	cat tests/fuzz/site_syntax.dict >> $@.tmp
	mv $@.tmp $@

# The objects stay once built: make would delete them as intermediates of
# the pattern rules, and a later `make fuzz-smoke` would build them again.
.SECONDARY: $(FUZZ_LIB_OBJS) $(FUZZ_BR_OBJS) $(FUZZ_NAMES:%=$(FUZZ_DIR)/obj/fuzz_%.o)

fuzz-build: $(FUZZ_BINS) $(FUZZ_DIR)/site.dict

# The library harness under MemorySanitizer (uninitialised reads; ASan does
# not see them). Only the library: the bridge links libinih, a system
# library MSan cannot see into. `make fuzz-msan [FUZZ_SECONDS=150]`.
FUZZ_MSAN     := -fsanitize=memory -fsanitize-memory-track-origins -fno-omit-frame-pointer -g -O1
FUZZ_MSAN_OBJS := $(patsubst lib/src/%.cpp,$(FUZZ_DIR)/msan/obj/%.o,$(LIB_SRCS))

$(FUZZ_DIR)/msan/obj/%.o: lib/src/%.cpp $(LIB_HDRS) tests/fuzz/fuzz.mk
	@mkdir -p $(@D)
	$(FUZZ_CXX) $(FUZZ_LIB_CXXFLAGS) $(FUZZ_MSAN) -fsanitize=fuzzer-no-link -c $< -o $@

$(FUZZ_DIR)/msan/fuzz_lib_api: tests/fuzz/fuzz_lib_api.c tests/fuzz/fuzz_common.h $(FUZZ_MSAN_OBJS)
	$(FUZZ_CC) -std=c11 -D_GNU_SOURCE -Wall -Wextra -Werror $(LIB_INCLUDES) -Itests/fuzz $(FUZZ_MSAN) \
	    -fsanitize=fuzzer -o $@ $< $(FUZZ_MSAN_OBJS) -lm

fuzz-msan: $(FUZZ_DIR)/msan/fuzz_lib_api
	sh tests/fuzz/run_fuzz.sh --seconds $(FUZZ_SECONDS) --build $(FUZZ_DIR)/msan lib_api

# $(1) seconds per harness
FUZZ_RUN = sh tests/fuzz/run_fuzz.sh --seconds $(1) --build $(FUZZ_DIR) $(FUZZ_NAMES)

fuzz: fuzz-build
	$(call FUZZ_RUN,$(FUZZ_SECONDS))

fuzz-smoke: fuzz-build
	sh tests/fuzz/run_fuzz.sh --seconds $(FUZZ_SMOKE_SECONDS) --build $(FUZZ_DIR) $(FUZZ_SMOKE_RUNS)

# Seeds: simulator logs (kleeman-lab and the fault scenarios, short), the
# site files, MAVLink packets packed with pymavlink. Written into
# tests/fuzz/corpus/ (committed); run by hand when a format changes.
fuzz-seeds: | $(SETUP_STAMP)
	$(PY) tests/fuzz/make_seeds.py --out tests/fuzz/corpus --work $(FUZZ_DIR)/seed-work

-include $(FUZZ_LIB_OBJS:.o=.d) $(FUZZ_BR_OBJS:.o=.d) $(patsubst %,$(FUZZ_DIR)/obj/fuzz_%.d,$(FUZZ_NAMES))
