# MAVLink 2 C headers, generated at build time by pymavlink's mavgen from the
# pinned pymavlink wheel's common.xml (never committed), and stand-alone rules
# for the MAVLink-output and node-clock unit tests.
#   make build/gen/mavlink/.stamp   generate the headers (the contract other rules depend on)
#   make test-mavlink               cmocka: tests/bridge/test_mavlink_out.c and
#                                   test_covariance.c (ASan/UBSan)
#   make test-node-clock            cmocka: tests/bridge/test_node_clock.c   (ASan/UBSan)
# bridge/bridge.mk also builds and runs both tests under test-bridge.
#
# Include generated headers only with -isystem $(BUILD)/gen/mavlink, and only
# through bridge/mav_priv.h, from bridge/mavlink_out.c and bridge/mav_input.c
# (the code that sees MAVLink; the covariance it sends is reshaped in
# bridge/covariance.c, no MAVLink type).

MAVLINK_GEN    := $(BUILD)/gen/mavlink
MAVLINK_STAMP  := $(MAVLINK_GEN)/.stamp
# The wheel ships its XML under pymavlink/dialects/v20/ (there is no
# message_definitions/ folder in the installed package).
MAVLINK_XML_PY := import pymavlink, os; print(os.path.join(os.path.dirname(pymavlink.__file__), "dialects", "v20", "common.xml"))

MAVOUT_DIR     := $(BUILD)/tests/mavlink
MAVOUT_CFLAGS  := -std=c11 -D_GNU_SOURCE -O1 -g -Wall -Wextra -Werror -Wconversion \
                  -Wdouble-promotion -Wshadow -MMD -MP \
                  -fsanitize=address,undefined -fno-omit-frame-pointer
MAVOUT_CPPFLAGS := -Ibridge -isystem $(MAVLINK_GEN)
MAVOUT_RUNENV  := ASAN_OPTIONS=detect_leaks=1 UBSAN_OPTIONS=halt_on_error=1:print_stacktrace=1

.PHONY: test-mavlink test-node-clock mavlink-gen

mavlink-gen: $(MAVLINK_STAMP)

# Regenerated when the pinned versions or this file change. Generated into a
# temporary folder and moved in place so an interrupted run leaves no half tree.
$(MAVLINK_STAMP): .ci/requirements.txt bridge/mavlink.mk | $(SETUP_STAMP)
	@xml="$$($(PY) -c '$(MAVLINK_XML_PY)')" && test -f "$$xml" || \
	    { echo "mavlink.mk: common.xml not found in the .venv's pymavlink (run make setup)" >&2; exit 1; }
	rm -rf $(MAVLINK_GEN).tmp $(MAVLINK_GEN)
	$(PY) -m pymavlink.tools.mavgen --lang=C --wire-protocol=2.0 \
	    --output=$(MAVLINK_GEN).tmp "$$($(PY) -c '$(MAVLINK_XML_PY)')"
	test -f $(MAVLINK_GEN).tmp/common/mavlink.h
	mv $(MAVLINK_GEN).tmp $(MAVLINK_GEN)
	touch $@

$(MAVOUT_DIR)/mavlink_out.o: bridge/mavlink_out.c bridge/mavlink_out.h bridge/mav_priv.h $(MAVLINK_STAMP)
	@mkdir -p $(@D)
	$(CC) $(MAVOUT_CPPFLAGS) $(MAVOUT_CFLAGS) -c -o $@ $<

$(MAVOUT_DIR)/mav_input.o: bridge/mav_input.c bridge/mavlink_out.h bridge/mav_priv.h $(MAVLINK_STAMP)
	@mkdir -p $(@D)
	$(CC) $(MAVOUT_CPPFLAGS) $(MAVOUT_CFLAGS) -c -o $@ $<

$(MAVOUT_DIR)/covariance.o: bridge/covariance.c bridge/covariance.h bridge/mavlink_out.h
	@mkdir -p $(@D)
	$(CC) $(MAVOUT_CPPFLAGS) $(MAVOUT_CFLAGS) -c -o $@ $<

$(MAVOUT_DIR)/node_clock.o: bridge/node_clock.c bridge/node_clock.h
	@mkdir -p $(@D)
	$(CC) $(MAVOUT_CPPFLAGS) $(MAVOUT_CFLAGS) -c -o $@ $<

# The test sees MAVLink too: it decodes what mavlink_out.c packed with the
# generated parser (it is a test, not part of the daemon).
$(MAVOUT_DIR)/test_mavlink_out.o: tests/bridge/test_mavlink_out.c bridge/mavlink_out.h $(MAVLINK_STAMP)
	@mkdir -p $(@D)
	$(CC) $(MAVOUT_CPPFLAGS) $(MAVOUT_CFLAGS) -c -o $@ $<

$(MAVOUT_DIR)/test_covariance.o: tests/bridge/test_covariance.c bridge/covariance.h bridge/mavlink_out.h $(MAVLINK_STAMP)
	@mkdir -p $(@D)
	$(CC) $(MAVOUT_CPPFLAGS) $(MAVOUT_CFLAGS) -c -o $@ $<

$(MAVOUT_DIR)/test_node_clock.o: tests/bridge/test_node_clock.c bridge/node_clock.h
	@mkdir -p $(@D)
	$(CC) $(MAVOUT_CPPFLAGS) $(MAVOUT_CFLAGS) -c -o $@ $<

$(MAVOUT_DIR)/test_mavlink_out: $(MAVOUT_DIR)/test_mavlink_out.o $(MAVOUT_DIR)/mavlink_out.o \
                                 $(MAVOUT_DIR)/mav_input.o $(MAVOUT_DIR)/covariance.o
	$(CC) -fsanitize=address,undefined -o $@ $^ -lcmocka -lm

$(MAVOUT_DIR)/test_covariance: $(MAVOUT_DIR)/test_covariance.o $(MAVOUT_DIR)/mavlink_out.o \
                                $(MAVOUT_DIR)/mav_input.o $(MAVOUT_DIR)/covariance.o
	$(CC) -fsanitize=address,undefined -o $@ $^ -lcmocka -lm

$(MAVOUT_DIR)/test_node_clock: $(MAVOUT_DIR)/test_node_clock.o $(MAVOUT_DIR)/node_clock.o
	$(CC) -fsanitize=address,undefined -o $@ $^ -lcmocka -lm

test-mavlink: $(MAVOUT_DIR)/test_mavlink_out $(MAVOUT_DIR)/test_covariance
	$(MAVOUT_RUNENV) $(MAVOUT_DIR)/test_mavlink_out
	$(MAVOUT_RUNENV) $(MAVOUT_DIR)/test_covariance

test-node-clock: $(MAVOUT_DIR)/test_node_clock
	$(MAVOUT_RUNENV) $<

-include $(MAVOUT_DIR)/*.d
