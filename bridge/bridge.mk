# beaconloc-bridge: the daemon (bridge/*.c), its cmocka tests
# (tests/bridge/test_*.c), its pytest suite and its replay benchmark.
#   make bridge                          the daemon (build/bridge/beaconloc-bridge)
#   make test-bridge                     every tests/bridge/test_*.c (cmocka)
#   make test-bridge-py                  pytest tests/bridge/ (also builds the
#                                        ASan/UBSan daemon beaconloc-bridge-asan)
#   make bench-bridge                    replay throughput + latency

BRIDGE_BIN      := $(BUILD)/bridge/beaconloc-bridge
BRIDGE_ASAN_BIN := $(BUILD)/bridge/beaconloc-bridge-asan
BRIDGE_OBJDIR   := $(BUILD)/bridge/obj
BRIDGE_SANDIR   := $(BUILD)/bridge/san
BRIDGE_TESTDIR  := $(BUILD)/tests/bridge
BRIDGE_CANGEN   := $(BUILD)/gen/can
BRIDGE_MAVGEN   := $(BUILD)/gen/mavlink
BRIDGE_MAVSTAMP := $(BRIDGE_MAVGEN)/.stamp
BRIDGE_LIB      := $(BUILD)/lib/libbeaconloc.a
BRIDGE_DBC      := hw_sim/beaconloc_sim/data/beaconloc.dbc

# The generated codec is named beaconloc_can (not beaconloc) so that its
# header cannot be confused with the library's umbrella header beaconloc.h.
# Beside it, from the same DBC, the bridge's sensor kinds (gen_frame_kinds.py):
# enum frame_kind and the payloads (frame_kinds.h), their unpackers
# (frame_kinds.c), the sensor table's list of kinds (sensor_kinds.c).
BRIDGE_CAN_C    := $(BRIDGE_CANGEN)/beaconloc_can.c
BRIDGE_CAN_H    := $(BRIDGE_CANGEN)/beaconloc_can.h
BRIDGE_GEN_NAMES := beaconloc_can frame_kinds sensor_kinds
BRIDGE_GEN_C    := $(BRIDGE_GEN_NAMES:%=$(BRIDGE_CANGEN)/%.c)

BRIDGE_SRCS     := $(sort $(wildcard bridge/*.c))
BRIDGE_OBJS     := $(patsubst bridge/%.c,$(BRIDGE_OBJDIR)/%.o,$(BRIDGE_SRCS)) \
                   $(BRIDGE_GEN_NAMES:%=$(BRIDGE_OBJDIR)/%.o)
BRIDGE_SANOBJS  := $(patsubst bridge/%.c,$(BRIDGE_SANDIR)/%.o,$(filter-out bridge/main.c,$(BRIDGE_SRCS))) \
                   $(BRIDGE_GEN_NAMES:%=$(BRIDGE_SANDIR)/%.o)
BRIDGE_TESTS_C  := $(sort $(wildcard tests/bridge/test_*.c))
BRIDGE_TESTS    := $(patsubst tests/bridge/%.c,$(BRIDGE_TESTDIR)/%,$(BRIDGE_TESTS_C))

# Objects that include mavlink_out.h (or MAVLink itself) wait for the
# generated headers of bridge/mavlink.mk.
BRIDGE_MAVDEP   := $(if $(wildcard bridge/mavlink_out.h),$(BRIDGE_MAVSTAMP))

BRIDGE_CPPFLAGS := -D_GNU_SOURCE -Ibridge $(LIB_INCLUDES) -I$(BRIDGE_CANGEN) \
                   -isystem $(BRIDGE_MAVGEN)
BRIDGE_CFLAGS   := -std=c11 -O2 -g -Wall -Wextra -Werror -Wconversion -Wdouble-promotion -MMD -MP
BRIDGE_SANFLAGS := -fsanitize=address,undefined -fno-omit-frame-pointer
BRIDGE_LDLIBS   := -linih -lm

ALL_TARGETS += $(BRIDGE_BIN)
UNIT_TESTS  += test-bridge
PY_TESTS    += test-bridge-py
TEST_BUILDS += $(BRIDGE_TESTS) $(BRIDGE_ASAN_BIN) $(BRIDGE_FAKECAN) $(BRIDGE_SLOWDNS)

.PHONY: bridge test-bridge test-bridge-py bench-bridge

bridge: $(BRIDGE_BIN)

# One recipe writes them all: whatever waits for $(BRIDGE_CAN_H) has them.
$(BRIDGE_GEN_C) $(BRIDGE_CAN_H) $(BRIDGE_CANGEN)/frame_kinds.h &: $(BRIDGE_DBC) \
        bridge/gen_frame_kinds.py .ci/requirements.txt | $(SETUP_STAMP)
	@mkdir -p $(BRIDGE_CANGEN)
	$(PY) -m cantools generate_c_source --database-name beaconloc_can \
	    -o $(BRIDGE_CANGEN) $(BRIDGE_DBC)
	$(PY) bridge/gen_frame_kinds.py $(BRIDGE_DBC) $(BRIDGE_CANGEN)

$(BRIDGE_GEN_NAMES:%=$(BRIDGE_OBJDIR)/%.o): $(BRIDGE_OBJDIR)/%.o: $(BRIDGE_CANGEN)/%.c $(BRIDGE_CAN_H)
	@mkdir -p $(@D)
	$(CC) $(BRIDGE_CPPFLAGS) $(BRIDGE_CFLAGS) -c -o $@ $<

$(BRIDGE_GEN_NAMES:%=$(BRIDGE_SANDIR)/%.o): $(BRIDGE_SANDIR)/%.o: $(BRIDGE_CANGEN)/%.c $(BRIDGE_CAN_H)
	@mkdir -p $(@D)
	$(CC) $(BRIDGE_CPPFLAGS) $(BRIDGE_CFLAGS) $(BRIDGE_SANFLAGS) -c -o $@ $<

# Objects that include the library's headers (beaconloc.h -> kinds.h) wait
# for its generated kinds' list (lib/lib.mk); the .d files keep later
# rebuilds exact.
$(BRIDGE_OBJS) $(BRIDGE_SANOBJS) $(BRIDGE_SANDIR)/main.o \
    $(patsubst tests/bridge/%.c,$(BRIDGE_TESTDIR)/obj/%.o,$(BRIDGE_TESTS_C)): | $(LIB_KINDS_H)

$(BRIDGE_OBJDIR)/%.o: bridge/%.c $(BRIDGE_CAN_H) $(BRIDGE_MAVDEP)
	@mkdir -p $(@D)
	$(CC) $(BRIDGE_CPPFLAGS) $(BRIDGE_CFLAGS) -c -o $@ $<

$(BRIDGE_SANDIR)/%.o: bridge/%.c $(BRIDGE_CAN_H) $(BRIDGE_MAVDEP)
	@mkdir -p $(@D)
	$(CC) $(BRIDGE_CPPFLAGS) $(BRIDGE_CFLAGS) $(BRIDGE_SANFLAGS) -c -o $@ $<

$(BRIDGE_BIN): $(BRIDGE_OBJS) $(BRIDGE_LIB)
	@mkdir -p $(@D)
	$(CC) -o $@ $(BRIDGE_OBJS) $(BRIDGE_LIB) $(BRIDGE_LDLIBS)

# The daemon built with ASan/UBSan, for the pytest suite's fuzz test.
$(BRIDGE_ASAN_BIN): $(BRIDGE_SANOBJS) $(BRIDGE_SANDIR)/main.o $(BRIDGE_LIB)
	@mkdir -p $(@D)
	$(CC) $(BRIDGE_SANFLAGS) -o $@ $(BRIDGE_SANDIR)/main.o $(BRIDGE_SANOBJS) \
	    $(BRIDGE_LIB) $(BRIDGE_LDLIBS)

# cmocka tests: one executable per tests/bridge/test_*.c, built with
# ASan/UBSan against sanitized bridge objects (all but main.o). A test that
# stands in for syscalls lists its wraps in BRIDGE_WRAP_<name>.
BRIDGE_WRAP_test_can_in := -Wl,--wrap=socket,--wrap=bind,--wrap=ioctl,--wrap=setsockopt,--wrap=getsockopt,--wrap=recvmsg,--wrap=close,--wrap=clock_gettime
# test_resolver stands a few names in for a name server (slow, failing).
BRIDGE_WRAP_test_resolver := -Wl,--wrap=getaddrinfo

$(BRIDGE_TESTDIR)/obj/%.o: tests/bridge/%.c $(BRIDGE_CAN_H) $(BRIDGE_MAVDEP)
	@mkdir -p $(@D)
	$(CC) $(BRIDGE_CPPFLAGS) $(BRIDGE_CFLAGS) $(BRIDGE_SANFLAGS) -c -o $@ $<

$(BRIDGE_TESTDIR)/test_%: $(BRIDGE_TESTDIR)/obj/test_%.o $(BRIDGE_SANOBJS) $(BRIDGE_LIB)
	$(CC) $(BRIDGE_SANFLAGS) -o $@ $< $(BRIDGE_SANOBJS) $(BRIDGE_LIB) \
	    $(BRIDGE_WRAP_test_$*) -lcmocka $(BRIDGE_LDLIBS)

# test_frame_kinds reads the DBC's text itself, to check the kinds against it.
$(BRIDGE_TESTDIR)/obj/test_frame_kinds.o: BRIDGE_CPPFLAGS += -DBRIDGE_DBC_PATH='"$(abspath $(BRIDGE_DBC))"'

# keep the test objects (intermediate files of the pattern chain)
.PRECIOUS: $(BRIDGE_TESTDIR)/obj/%.o

test-bridge: $(BRIDGE_TESTS)
	@set -e; for t in $(BRIDGE_TESTS); do echo "== $$t"; \
	    ASAN_OPTIONS=detect_leaks=1 UBSAN_OPTIONS=halt_on_error=1:print_stacktrace=1 $$t; done

# Test-only LD_PRELOAD shim standing in for a CAN socket (no CAN in this
# kernel) so pytest can drive the daemon's live path.
BRIDGE_FAKECAN := $(BRIDGE_TESTDIR)/fake_can_preload.so
$(BRIDGE_FAKECAN): tests/bridge/fake_can_preload.c
	@mkdir -p $(@D)
	$(CC) -std=c11 -O2 -Wall -Wextra -Werror -shared -fPIC -o $@ $< -ldl

# Test-only LD_PRELOAD shim: a name server that answers late (or fails), for
# the host-fault tests (tests/bridge/test_bridge_hostfaults.py).
BRIDGE_SLOWDNS := $(BRIDGE_TESTDIR)/slow_dns_preload.so
$(BRIDGE_SLOWDNS): tests/bridge/slow_dns_preload.c
	@mkdir -p $(@D)
	$(CC) -std=c11 -O2 -Wall -Wextra -Werror -shared -fPIC -o $@ $< -ldl

test-bridge-py: $(BRIDGE_BIN) $(BRIDGE_ASAN_BIN) $(BRIDGE_FAKECAN) $(BRIDGE_SLOWDNS) | $(SETUP_STAMP)
	BL_BUILD=$(abspath $(BUILD)) $(PYTEST) -q -n 3 tests/bridge

bench-bridge: $(BRIDGE_BIN) | $(SETUP_STAMP)
	$(PY) tests/bridge/bench_replay.py --bridge $(BRIDGE_BIN) --out $(BUILD)/bench/bridge

-include $(BRIDGE_OBJS:.o=.d) $(BRIDGE_SANOBJS:.o=.d) $(BRIDGE_SANDIR)/main.d $(patsubst tests/bridge/%.c,$(BRIDGE_TESTDIR)/obj/%.d,$(BRIDGE_TESTS_C))
