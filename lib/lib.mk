# lib/lib.mk — the estimator library (libbeaconloc) and its cmocka tests.
#
#   build/lib/libbeaconloc.a         double (default; what the bridge links)
#   build/lib/float/libbeaconloc.a   -DBL_USE_FLOAT=1
#   build/lib/san/libbeaconloc.a     double with ASan/UBSan (tests only)
#   build/lib/nobearing/libbeaconloc.a  double, -DBL_WITH_KINDS=0 (every kind
#                                    off: bearings, ranges, team, sonar; tests
#                                    only: LIB_NOBEARING_TESTS below)
#   make test-lib                    every tests/lib/test_*.c as its own cmocka
#                                    executable against the double, float and
#                                    sanitized builds, plus check-lib-clink
#   make check-lib-clink             pure-C link (gcc prog.c lib.a -lm, no
#                                    libstdc++) and `nm -u` audit of both archives
#
# Every lib/src/*.cpp is compiled into the library (wildcard); every
# lib/include/beaconloc/aid_*.h is one measurement kind, listed in
# $(LIB_KINDS_H) (beaconloc/kinds_list.h, generated below); every
# tests/lib/test_*.c except test_clink.c is a cmocka test (test_clink.c is the
# plain C program of check-lib-clink: no cmocka, no C++ runtime).
# LIB_INCLUDES (the include path), LIB_KINDS_H: the top-level Makefile.
# Header dependencies: each object and test records the headers it includes
# (-MMD -MP, .d files beside it, included below). Compilers: $(CC), $(CXX),
# $(AR). Eigen: EIGEN_CFLAGS from `pkg-config --cflags eigen3` as -isystem
# (Debian's path when pkg-config has no eigen3); lib/firmware.mk uses it too.

LIB_SRCS      := $(sort $(wildcard lib/src/*.cpp))
# Every library header (for fragments that depend on all of them, e.g.
# tests/fuzz/fuzz.mk; the rules here use the .d files instead).
LIB_HDRS      := $(wildcard lib/include/*.h lib/include/beaconloc/*.h lib/src/*.hpp) $(LIB_KINDS_H)
LIB_KIND_HDRS := $(sort $(wildcard lib/include/beaconloc/aid_*.h))
EIGEN_CFLAGS  := $(patsubst -I%,-isystem %,$(shell pkg-config --cflags eigen3 2>/dev/null))
ifeq ($(strip $(EIGEN_CFLAGS)),)
EIGEN_CFLAGS  := -isystem /usr/include/eigen3
endif
LIB_DEPFLAGS  := -MMD -MP
LIB_TEST_SRCS := $(filter-out tests/lib/test_clink.c,$(sort $(wildcard tests/lib/test_*.c)))
LIB_TEST_NAMES := $(basename $(notdir $(LIB_TEST_SRCS)))

# Extra libraries of one test: LIB_TEST_LDLIBS_<test name> (test_config reads
# the site file with libinih, as the bridge does).
LIB_TEST_LDLIBS_test_config := -linih

LIB_WARN      := -Wall -Wextra -Werror -Wconversion -Wdouble-promotion -Wshadow
# -fno-threadsafe-statics: no __cxa_guard_*; EIGEN_GEMM_TO_COEFFBASED_THRESHOLD:
# keep fixed-size products off Eigen's GEMM kernel (which references malloc).
LIB_CXXFLAGS  := -std=c++17 -O2 -fno-exceptions -fno-rtti -fno-threadsafe-statics \
                 -DEIGEN_NO_MALLOC -DEIGEN_GEMM_TO_COEFFBASED_THRESHOLD=1000 \
                 $(EIGEN_CFLAGS) $(LIB_INCLUDES) $(LIB_WARN)
LIB_TEST_CFLAGS := -std=c11 -O1 -g $(LIB_INCLUDES) -Itests/lib -Wall -Wextra -Werror \
                   -Wno-unused-parameter
LIB_SAN       := -fsanitize=address,undefined -fno-omit-frame-pointer -fno-sanitize-recover=all

# $(1) variant dir under build/lib ('' = default), $(2) extra compile flags,
# $(3) extra test link flags
define LIB_VARIANT
$(BUILD)/lib/$(1)obj/%.o: lib/src/%.cpp lib/lib.mk | $(LIB_KINDS_H)
	@mkdir -p $$(@D)
	$(CXX) $(LIB_CXXFLAGS) $(LIB_DEPFLAGS) $(2) -c $$< -o $$@

$(BUILD)/lib/$(1)libbeaconloc.a: $(patsubst lib/src/%.cpp,$(BUILD)/lib/$(1)obj/%.o,$(LIB_SRCS))
	@mkdir -p $$(@D)
	rm -f $$@
	$(AR) rcs $$@ $$^

$(BUILD)/lib/$(1)tests/%: tests/lib/%.c $(BUILD)/lib/$(1)libbeaconloc.a lib/lib.mk | $(LIB_KINDS_H)
	@mkdir -p $$(@D)
	$(CC) $(LIB_TEST_CFLAGS) $(LIB_DEPFLAGS) $(2) $$< $(BUILD)/lib/$(1)libbeaconloc.a $(3) $$(LIB_TEST_LDLIBS_$$*) -lcmocka -lm -o $$@

-include $(patsubst lib/src/%.cpp,$(BUILD)/lib/$(1)obj/%.d,$(LIB_SRCS)) \
         $(addprefix $(BUILD)/lib/$(1)tests/,$(addsuffix .d,$(LIB_TEST_NAMES)))
endef

# The kinds' list (beaconloc/kinds.h): each kind's header and BL_KINDS, from
# the BL_<KIND>_KIND_ORDER of every lib/include/beaconloc/aid_<kind>.h
# (lib/gen_kinds_list.sh: POSIX sh, sed, awk, sort; no Python, as a firmware
# build). Made at every build (a header added or removed changes the list;
# FORCE: no file's date shows a removal) and replaced only when it differs,
# so nothing is rebuilt for an unchanged list. Every object that includes it
# records it in its .d file; a clean build makes it first (order-only
# prerequisites here and in the other fragments).
$(LIB_KINDS_H): lib/gen_kinds_list.sh FORCE
	@mkdir -p $(@D)
	@sh lib/gen_kinds_list.sh $(LIB_KIND_HDRS) > $@.tmp
	@if cmp -s $@.tmp $@; then rm -f $@.tmp; else mv $@.tmp $@; echo "gen_kinds_list: $@"; fi

.PHONY: FORCE
FORCE:

$(eval $(call LIB_VARIANT,,-DEIGEN_NO_DEBUG,))
$(eval $(call LIB_VARIANT,float/,-DBL_USE_FLOAT=1 -DEIGEN_NO_DEBUG,))
$(eval $(call LIB_VARIANT,san/,$(LIB_SAN) -g,$(LIB_SAN)))
# Without bearings and ranges (common.h BL_WITH_BEARINGS 0, BL_WITH_RANGES 0,
# as the M4 example builds): the library and the few tests that build that
# way, so the switches cannot rot (every other test uses the bearing or range
# API and runs in the three above).
$(eval $(call LIB_VARIANT,nobearing/,-DBL_WITH_KINDS=0 -DEIGEN_NO_DEBUG,))
LIB_NOBEARING_TESTS := test_build_switch test_filter_pulse test_filter_errors test_solver_bearing test_solver_range

LIB_TEST_BINS := $(foreach v,/ /float/ /san/,$(addprefix $(BUILD)/lib$(v)tests/,$(LIB_TEST_NAMES))) \
                 $(addprefix $(BUILD)/lib/nobearing/tests/,$(LIB_NOBEARING_TESTS))

ALL_TARGETS += $(BUILD)/lib/libbeaconloc.a $(BUILD)/lib/float/libbeaconloc.a
UNIT_TESTS  += test-lib
TEST_BUILDS += $(LIB_TEST_BINS)

.PHONY: lib test-lib check-lib-clink
lib: $(BUILD)/lib/libbeaconloc.a $(BUILD)/lib/float/libbeaconloc.a

# test_localizer's input: hardware-simulator runs turned into the
# localizer's inputs (tests/lib/localizer_input.py), made here, never
# committed. Scenario and seconds simulated:
LOC_DATA_DIR := $(BUILD)/tests/lib/data
LOC_RUNS     := kleeman-lab:40 echo-storm:40 kidnap:75 encoder-silence:40 controller-restart:90
LOC_DATA     := $(foreach r,$(LOC_RUNS),$(LOC_DATA_DIR)/$(word 1,$(subst :, ,$(r))).txt)
$(LOC_DATA_DIR)/%.txt: tests/lib/localizer_input.py hw_sim/beaconloc_sim/data/beaconloc.dbc \
                       hw_sim/beaconloc_sim/data/scenarios/%.scenario.ini \
                       hw_sim/beaconloc_sim/data/scenarios/kleeman-lab.ini | $(SETUP_STAMP)
	$(PY) tests/lib/localizer_input.py $* \
	    $(word 2,$(subst :, ,$(filter $*:%,$(LOC_RUNS)))) 1 $(LOC_DATA_DIR)/$*

# test_team's input: team simulator runs turned into the coordinator's
# inputs on one timebase (tests/lib/team_input.py), made here, never
# committed. Scenario and seconds simulated (the leap-frog cut after its
# third leap):
TEAM_DATA_DIR := $(BUILD)/tests/lib/team
TEAM_RUNS     := team-static:60 team-leapfrog:66
TEAM_DATA     := $(foreach r,$(TEAM_RUNS),$(TEAM_DATA_DIR)/$(word 1,$(subst :, ,$(r))).txt)
$(TEAM_DATA_DIR)/%.txt: tests/lib/team_input.py hw_sim/beaconloc_sim/data/beaconloc.dbc \
                        hw_sim/beaconloc_sim/data/scenarios/%.scenario.ini | $(SETUP_STAMP)
	$(PY) tests/lib/team_input.py $* \
	    $(word 2,$(subst :, ,$(filter $*:%,$(TEAM_RUNS)))) 1 $(TEAM_DATA_DIR)/$*

test-lib: $(LIB_TEST_BINS) check-lib-clink $(LOC_DATA) $(TEAM_DATA)
	@set -e; for t in $(LIB_TEST_BINS); do echo "== $$t"; \
	  BL_LOCALIZER_DATA=$(LOC_DATA_DIR) BL_TEAM_DATA=$(TEAM_DATA_DIR) $$t; done

# Pure C program, plain C compiler ($(CC)), no libstdc++: the link itself proves no C++
# runtime is needed; nm -u proves no heap and no C++ runtime references.
LIB_FORBIDDEN := '(__cxa_|__gxx_|_Znw|_Zna|_Zdl|_Zda|_ZSt|_Unwind_|^malloc$$|^free$$|^calloc$$|^realloc$$|operator)'
check-lib-clink: tests/lib/test_clink.c $(BUILD)/lib/libbeaconloc.a $(BUILD)/lib/float/libbeaconloc.a $(LIB_KINDS_H)
	@mkdir -p $(BUILD)/lib/clink
	$(CC) -std=c99 -pedantic -Wall -Wextra -Werror $(LIB_INCLUDES) tests/lib/test_clink.c \
	    $(BUILD)/lib/libbeaconloc.a -lm -o $(BUILD)/lib/clink/clink_double
	$(CC) -std=c99 -pedantic -Wall -Wextra -Werror -DBL_USE_FLOAT=1 $(LIB_INCLUDES) tests/lib/test_clink.c \
	    $(BUILD)/lib/float/libbeaconloc.a -lm -o $(BUILD)/lib/clink/clink_float
	$(BUILD)/lib/clink/clink_double
	$(BUILD)/lib/clink/clink_float
	@set -e; for a in $(BUILD)/lib/libbeaconloc.a $(BUILD)/lib/float/libbeaconloc.a; do \
	  bad=$$(nm -u $$a | awk 'NF>=2 {print $$2}' | grep -E $(LIB_FORBIDDEN) || true); \
	  if [ -n "$$bad" ]; then echo "check-lib-clink: $$a references: $$bad"; exit 1; fi; \
	  echo "check-lib-clink: $$a: nm -u clean ($$(nm -u $$a | awk 'NF>=2 {print $$2}' | sort -u | tr '\n' ' '))"; \
	done
