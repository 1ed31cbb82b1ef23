# The site schema (hw_sim/beaconloc_sim/data/site_schema.toml): every key of
# the site file declared once. At build time it gives the bridge's C tables
# (build/gen/site/site_keys.h: parser, defaults, [tuning] struct, geometry,
# bl_config mapping), never committed; the simulator reads the schema itself.
#   make docs-site-keys   rewrite the key table of docs/bridge.md and the MAVLink
#                         parameter table of docs/mavlink.md from it
#                         (tests/sim/test_site_schema.py fails while they differ)

SITE_SCHEMA     := hw_sim/beaconloc_sim/data/site_schema.toml
SITE_SCHEMA_PY  := hw_sim/beaconloc_sim/site_schema.py
SITE_GEN        := $(BUILD)/gen/site
SITE_KEYS_H     := $(SITE_GEN)/site_keys.h
SITE_DOCS       := docs/bridge.md

.PHONY: docs-site-keys

$(SITE_KEYS_H): $(SITE_SCHEMA) $(SITE_SCHEMA_PY) | $(SETUP_STAMP)
	@mkdir -p $(@D)
	$(PY) -m beaconloc_sim.site_schema c-header -o $@.tmp
	mv $@.tmp $@

docs-site-keys: | $(SETUP_STAMP)
	$(PY) -m beaconloc_sim.site_schema docs-update -o $(SITE_DOCS)
	$(PY) -m beaconloc_sim.site_schema params-update -o docs/mavlink.md

# Every bridge object includes config.h (-> tuning.h -> site_keys.h): the
# header first. (The compilers' .d files keep later rebuilds exact.)
BRIDGE_CPPFLAGS += -I$(SITE_GEN)
$(BRIDGE_OBJS) $(BRIDGE_SANOBJS) $(BRIDGE_SANDIR)/main.o \
    $(patsubst tests/bridge/%.c,$(BRIDGE_TESTDIR)/obj/%.o,$(BRIDGE_TESTS_C)) \
    $(patsubst bridge/%.c,$(BUILD)/fuzz/obj/bridge/%.o,$(BRIDGE_SRCS)) \
    $(patsubst tests/fuzz/%.c,$(BUILD)/fuzz/obj/%.o,$(wildcard tests/fuzz/fuzz_*.c)): $(SITE_KEYS_H)
# tests/lib/test_config.c reads the site file through the schema's mapping.
# (lib.mk expands LIB_TEST_CFLAGS into its rules when it is read; the
# per-test flags are read when the rule runs, and gcc takes -I anywhere.)
LIB_TEST_LDLIBS_test_config += -I$(SITE_GEN)
$(foreach v,/ /float/ /san/,$(BUILD)/lib$(v)tests/test_config): $(SITE_KEYS_H)
