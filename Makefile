# beaconloc — top-level build.
#   make            build the library and the bridge daemon
#   make test       install what is missing, then run every test suite
#   make demo       live run: simulator -> vcan0 -> bridge -> MAVLink
#   make install    the daemon, its systemd unit and manual (bridge/install.mk)
# Each part keeps its own rules in a fragment included below; a fragment adds
# its test targets to UNIT_TESTS / PY_TESTS so `make test` picks them up.

BUILD   ?= build
VENV    ?= .venv
PY      := $(CURDIR)/$(VENV)/bin/python
PYTEST  := $(PY) -m pytest
SETUP_STAMP := $(VENV)/.beaconloc-setup

# The library's include path: lib/include and the kinds' list that the build
# generates from its kinds' headers (lib/lib.mk, beaconloc/kinds.h). Whatever
# compiles against the library uses LIB_INCLUDES and waits for LIB_KINDS_H
# (named here: lib/bench.mk and lib/firmware.mk are read before lib/lib.mk).
LIB_GEN      := $(BUILD)/gen/lib
LIB_KINDS_H  := $(LIB_GEN)/beaconloc/kinds_list.h
LIB_INCLUDES := -Ilib/include -I$(LIB_GEN)

CC      ?= gcc
CXX     ?= g++

.DEFAULT_GOAL := all
.PHONY: all setup test test-unit test-py test-integration demo clean \
        bench-speed bench-accuracy

UNIT_TESTS :=
PY_TESTS   :=
# What the suites run, built first by `make test` with one job per core
# (fragments add their test executables, preload libraries, fuzzers).
TEST_BUILDS =
NPROC   := $(shell nproc 2>/dev/null || echo 1)

# Installs Debian packages and the .venv (idempotent; quick when done).
setup: $(SETUP_STAMP)
$(SETUP_STAMP): .ci/setup .ci/requirements.txt hw_sim/pyproject.toml
	bash .ci/setup

# Fragments: lib/*.mk, bridge/*.mk, hw_sim/*.mk, tests/*/*.mk (alphabetical).
include $(sort $(wildcard lib/*.mk)) $(sort $(wildcard bridge/*.mk)) \
        $(sort $(wildcard hw_sim/*.mk)) $(sort $(wildcard tests/*/*.mk))

all: $(ALL_TARGETS)

test-unit: $(UNIT_TESTS)
test-py: $(PY_TESTS)

# The vcan suite (tests/integration, in UML guests at nice -10) is the longest
# and mostly waits on real time: it starts as soon as the daemon it runs is
# built, and the rest is built and tested beside it, one suite after the other,
# at the lowest CPU priority (tests/vm/batch.sh), in the time the guests leave
# (docs/testing.md "How long make test takes").
.PHONY: test-rest test-rest-batch
# On a failure the vcan suite's failed cases are shown again last: its output
# comes first in the log, before the other suites', and a log's tail is what
# a CI report keeps.
test: setup
	$(MAKE) -j$(NPROC) $(IT_BUILDS)
	$(MAKE) -j2 --output-sync=recurse test-integration test-rest-batch || \
	    { $(VM_RUN) --results $(IT_RESULTS) --junit junit.xml --max-chars 1500 --report; exit 1; }
test-rest-batch:
	setsid -w sh tests/vm/batch.sh $(MAKE) test-rest
test-rest:
	$(MAKE) -j$(NPROC) all $(TEST_BUILDS)
	$(MAKE) test-unit
	$(MAKE) test-py

# C and C++ style of lib/ and bridge/ (lib/.clang-format, bridge/.clang-format;
# Debian's clang-format 14): `make format` rewrites, `make check-format`
# (a unit test) fails on any file that differs from its formatted self.
FORMAT_SRCS = $(shell git ls-files 'lib/*.c' 'lib/*.h' 'lib/*.cpp' 'lib/*.hpp' 'bridge/*.c' 'bridge/*.h' 2>/dev/null)
.PHONY: format check-format
format:
	clang-format -i $(FORMAT_SRCS)
check-format: $(SETUP_STAMP)
	clang-format --dry-run --Werror $(FORMAT_SRCS)
	@echo "check-format: $(words $(FORMAT_SRCS)) files formatted"
UNIT_TESTS += check-format

clean:
	rm -rf $(BUILD)
