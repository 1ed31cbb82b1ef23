# lib/firmware.mk — Cortex-M4F fitness of libbeaconloc.
#
#   make size-m4        cross-build the library (float, -Os) and the bare-metal
#                       example lib/examples/firmware_m4 (STM32F407 memory map)
#                       with Debian's arm-none-eabi toolchain + newlib nano, then
#                       print flash/RAM of the library and of the whole image,
#                       sizeof(bl_filter), the worst per-function stack use
#                       (-fstack-usage) and the worst call chain
#                       (-fcallgraph-info=su). Last line machine-readable.
#   make run-m4-qemu    the same firmware with a simulated board on QEMU's
#                       netduinoplus2 (Cortex-M4F), fed a hardware-simulator
#                       run through semihosting; its estimates judged against
#                       the simulator's truth (needs the Debian package
#                       qemu-system-arm).
#   make bench-m4       instructions per fuse_pulse / predict / sequencer
#                       detection on the emulated M4 (QEMU -icount).
#   make check-m4-build (in UNIT_TESTS) the cross build links with plain gcc
#                       (no libstdc++); fails if the image contains C++
#                       runtime or heap functions, or if the cross-built
#                       library archive references any (nm -u), as
#                       check-lib-clink does for the host builds.
#
# The example is a pulse-only board: built with BL_WITH_KINDS=0 (common.h),
# every measurement kind's switch off, those of kinds added later too: no
# bearing, range, team or sonar fusion, no triangulation or trilateration
# start, no buffers of theirs (with the sonar ring's correctors and fusion,
# sonar.h, the library was 32.9 KiB and a localizer 2,088 B, over both
# targets). A board that wants a kind sets its switch to 1 beside it.
#
# Targets (issue 2): library <= 32 KiB flash, one localizer (filter +
# sequencer + policy) <= 2 KiB RAM, stack <= 2 KiB. Reported, not enforced.

M4_PREFIX   ?= arm-none-eabi-
M4_DIR      := $(BUILD)/m4
FW_HOST_DIR := $(BUILD)/fw_host
FW_HOST_BIN := $(FW_HOST_DIR)/firmware_host
M4_ARCH     := -mcpu=cortex-m4 -mthumb -mfpu=fpv4-sp-d16 -mfloat-abi=hard
M4_COMMON   := $(M4_ARCH) -Os -g -ffunction-sections -fdata-sections -fstack-usage \
               -fcallgraph-info=su -DBL_USE_FLOAT=1 -DBL_MAX_BEACONS=8 -DBL_MAX_RECEIVERS=8 \
               -DBL_WITH_KINDS=0 $(LIB_INCLUDES)
# EIGEN_UNROLLING_LIMIT=0: Eigen's fixed-size expressions as loops, not
# unrolled (Eigen's default limit is 110): on the M4 both smaller and
# faster (size-m4 library flash 33,153 -> 29,307 B; bench-m4 fuse_pulse
# 9,339 -> 7,446 and predict_odometry 11,279 -> 8,851 instructions,
# measured on this revision, not analysed further). The host builds keep
# Eigen's default.
# EIGEN_CFLAGS: pkg-config's eigen3 as -isystem (lib/lib.mk, parsed after
# this file: hence = here). Eigen is headers only, the host's serve the
# cross build.
M4_CXXFLAGS  = $(M4_COMMON) -std=c++17 -fno-exceptions -fno-rtti -fno-threadsafe-statics \
               -DEIGEN_NO_MALLOC -DEIGEN_GEMM_TO_COEFFBASED_THRESHOLD=1000 -DEIGEN_NO_DEBUG \
               -DEIGEN_UNROLLING_LIMIT=0 \
               $(EIGEN_CFLAGS) -Wall -Wextra -Werror -Wconversion -Wdouble-promotion
M4_CFLAGS   := $(M4_COMMON) -std=c11 -Wall -Wextra -Werror -Wdouble-promotion
M4_LDFLAGS  := $(M4_ARCH) --specs=nano.specs --specs=nosys.specs -nostartfiles \
               -Tlib/examples/firmware_m4/stm32f4.ld -Wl,--gc-sections

M4_LIB_SRCS := $(sort $(wildcard lib/src/*.cpp))
M4_LIB_OBJS := $(patsubst lib/src/%.cpp,$(M4_DIR)/lib/%.o,$(M4_LIB_SRCS))
M4_EX_SRCS  := $(sort $(wildcard lib/examples/firmware_m4/*.c))
M4_EX_OBJS  := $(patsubst lib/examples/firmware_m4/%.c,$(M4_DIR)/example/%.o,$(M4_EX_SRCS))
# (with the kinds' list the build generates, lib/lib.mk)
M4_HDRS     := $(wildcard lib/include/*.h lib/include/beaconloc/*.h lib/src/*.hpp lib/examples/firmware_m4/*.h) \
               $(LIB_KINDS_H)
M4_ELF      := $(M4_DIR)/firmware_m4.elf

$(M4_DIR)/lib/%.o: lib/src/%.cpp $(M4_HDRS) lib/firmware.mk
	@mkdir -p $(@D)
	$(M4_PREFIX)g++ $(M4_CXXFLAGS) -c $< -o $@

$(M4_DIR)/example/%.o: lib/examples/firmware_m4/%.c $(M4_HDRS) lib/firmware.mk
	@mkdir -p $(@D)
	$(M4_PREFIX)gcc $(M4_CFLAGS) -c $< -o $@

$(M4_DIR)/libbeaconloc.a: $(M4_LIB_OBJS)
	rm -f $@
	$(M4_PREFIX)ar rcs $@ $^

# Linked with gcc, not g++: no libstdc++ on the firmware either.
$(M4_ELF): $(M4_EX_OBJS) $(M4_DIR)/libbeaconloc.a lib/examples/firmware_m4/stm32f4.ld
	$(M4_PREFIX)gcc $(M4_LDFLAGS) -Wl,-Map=$(M4_DIR)/firmware_m4.map $(M4_EX_OBJS) \
	    $(M4_DIR)/libbeaconloc.a -lm -o $@

# C++ runtime or heap functions in the firmware image, or referenced by the
# cross-built library (which --gc-sections could hide from the image): a
# hard failure, with the library functions that reference the heap (from
# -fcallgraph-info). size-m4 prints heap_refs in its last line.
M4_CXXRT := '(__cxa_|__gxx_|_Znw|_Zna|_Zdl|_Zda|_ZSt|_Unwind_)'
M4_HEAP  := '^(malloc|free|calloc|realloc|_malloc_r|_free_r|_calloc_r|_realloc_r)$$'

# The same firmware (main.c, startup, linker script) with the simulated board
# (sim/board_sim.c instead of board.c), run on QEMU's netduinoplus2
# (STM32F405, Cortex-M4F): semihosting prints the tracking error against
# the truth and sets QEMU's exit status.
M4_SIM_ELF  := $(M4_DIR)/firmware_m4_sim.elf
M4_SIM_OBJS := $(filter-out $(M4_DIR)/example/board.o,$(M4_EX_OBJS)) $(M4_DIR)/example/sim/board_sim.o
QEMU_ARM    ?= qemu-system-arm

$(M4_DIR)/example/sim/%.o: lib/examples/firmware_m4/sim/%.c $(M4_HDRS) lib/firmware.mk
	@mkdir -p $(@D)
	$(M4_PREFIX)gcc $(M4_CFLAGS) -c $< -o $@

$(M4_SIM_ELF): $(M4_SIM_OBJS) $(M4_DIR)/libbeaconloc.a lib/examples/firmware_m4/stm32f4.ld
	$(M4_PREFIX)gcc $(M4_LDFLAGS) $(M4_SIM_OBJS) $(M4_DIR)/libbeaconloc.a -lm -o $@

# Instruction counts per call on the emulated M4 (QEMU -icount: 1 instruction
# = 1 ns of virtual time, read through SysTick). Last line machine-readable.
M4_BENCH_ELF := $(M4_DIR)/bench_m4.elf
$(M4_BENCH_ELF): $(M4_DIR)/example/sim/bench_m4.o $(M4_DIR)/example/startup_stm32f4.o $(M4_DIR)/libbeaconloc.a \
                 lib/examples/firmware_m4/stm32f4.ld
	$(M4_PREFIX)gcc $(M4_LDFLAGS) $(M4_DIR)/example/sim/bench_m4.o $(M4_DIR)/example/startup_stm32f4.o \
	    $(M4_DIR)/libbeaconloc.a -lm -o $@

.PHONY: bench-m4
bench-m4: $(M4_BENCH_ELF)
	timeout 600 $(QEMU_ARM) -M netduinoplus2 -nographic -monitor none -serial none -icount shift=0 \
	    -semihosting-config enable=on,target=native -kernel $(M4_BENCH_ELF)

# Its world: 40 s of kleeman-lab from the hardware simulator, as the host
# board (sim/board_log.c) hands it to main.c (--board-dump); made here, never
# committed. The estimates the emulated M4 writes are judged against the
# simulator's truth by the benchmarks' code (tests/bench/firmware.py --check).
M4_SIM_RUN  := $(M4_DIR)/sim-kleeman-lab
$(M4_SIM_RUN).board: $(FW_HOST_BIN) | $(SETUP_STAMP)
	$(VENV)/bin/beaconloc-sim run kleeman-lab --duration 40 --seed 1 --log $(M4_SIM_RUN).log \
	    --truth $(M4_SIM_RUN).truth.csv
	$(FW_HOST_BIN) --log $(M4_SIM_RUN).log --estimates $(M4_SIM_RUN).host.csv --board-dump $@

.PHONY: run-m4-qemu
run-m4-qemu: $(M4_SIM_ELF) $(M4_SIM_RUN).board
	timeout 300 $(QEMU_ARM) -M netduinoplus2 -nographic -monitor none -serial none \
	    -semihosting-config enable=on,target=native,arg=firmware,arg=$(M4_SIM_RUN).board,arg=$(M4_SIM_RUN).est.csv \
	    -kernel $(M4_SIM_ELF)
	$(PY) tests/bench/firmware.py --check $(M4_SIM_RUN).est.csv --truth $(M4_SIM_RUN).truth.csv \
	    --max-rmse-mm 60

.PHONY: size-m4 check-m4-build
check-m4-build: $(M4_ELF)
	@bad=$$($(M4_PREFIX)nm $(M4_ELF) | awk '{print $$NF}' | grep -E $(M4_CXXRT) || true); \
	if [ -n "$$bad" ]; then echo "check-m4-build: FAIL: $(M4_ELF) contains C++ runtime: $$bad"; exit 1; fi; \
	heap=$$($(M4_PREFIX)nm $(M4_ELF) | awk '{print $$NF}' | grep -E $(M4_HEAP) | tr '\n' ' '); \
	libheap=$$($(M4_PREFIX)nm -u $(M4_DIR)/libbeaconloc.a | awk 'NF>=2 {print $$2}' | grep -E $(M4_HEAP)'|'$(M4_CXXRT) | sort -u | tr '\n' ' '); \
	if [ -n "$$heap$$libheap" ]; then \
	  who=$$(grep -h 'targetname: "\(malloc\|free\|calloc\|realloc\)"' $(M4_DIR)/lib/*.ci | sed 's/.*sourcename: "\([^"]*\)".*/\1/' | sort -u | $(M4_PREFIX)c++filt | cut -c1-160 | tr '\n' ';'); \
	  echo "check-m4-build: FAIL: heap / C++ runtime: image has ($$heap), library references ($$libheap); referenced from: $$who"; \
	  exit 1; fi; \
	echo "check-m4-build: OK: $(M4_ELF) links (arm-none-eabi-gcc, newlib nano, no C++ runtime, no heap in the image or the library)"

size-m4: $(M4_ELF) $(M4_DIR)/example/sim/size_probe.o | $(SETUP_STAMP)
	$(PY) lib/examples/firmware_m4/size_report.py --elf $(M4_ELF) --map $(M4_DIR)/firmware_m4.map \
	    --lib-objs $(M4_DIR)/lib --example-objs $(M4_DIR)/example --prefix $(M4_PREFIX) \
	    --probe $(M4_DIR)/example/sim/size_probe.o

UNIT_TESTS += check-m4-build
TEST_BUILDS += $(M4_ELF) $(M4_SIM_ELF)
# The emulator run joins the unit tests wherever qemu-system-arm is installed
# (Debian package qemu-system-arm; .ci/setup should install it).
ifneq ($(shell command -v $(QEMU_ARM) 2>/dev/null),)
UNIT_TESTS += run-m4-qemu
endif

# ---- the firmware main loop on the host, on simulator logs ----------------
# The same main.c (renamed firmware_main) with sim/board_log.c: a candump log
# written by the simulator in, the bridge's estimates CSV out; the float
# library as on the M4. Frames decoded by the cantools-generated codec
# (bridge/bridge.mk generates it), encoder samples mapped onto the receiver
# clock by bridge/node_clock.c (host only: one clock on a real board).
#   make bench-firmware   echo-storm and kleeman-lab, 20 seeds each: the
#                         firmware's position RMSE against the bridge's on the
#                         same logs, judged by tests/bench/accuracy.py's code.
#                         Last line (kleeman-lab):
#   firmware scenario=kleeman-lab seeds=20 rmse_mm=<x> bridge_rmse_mm=<x> ratio=<firmware/bridge>
FW_HOST_CAN   := $(BUILD)/gen/can
FW_HOST_FLAGS := -std=c11 -O2 -g -Wall -Wextra -Werror -Wdouble-promotion -DBL_USE_FLOAT=1 \
                 $(LIB_INCLUDES) -Ibridge -I$(FW_HOST_CAN)

$(FW_HOST_DIR)/main.o: lib/examples/firmware_m4/main.c $(M4_HDRS) lib/firmware.mk
	@mkdir -p $(@D)
	$(CC) $(FW_HOST_FLAGS) -Dmain=firmware_main -c $< -o $@

$(FW_HOST_DIR)/board_log.o: lib/examples/firmware_m4/sim/board_log.c $(M4_HDRS) bridge/node_clock.h \
                            $(FW_HOST_CAN)/beaconloc_can.h lib/firmware.mk
	@mkdir -p $(@D)
	$(CC) $(FW_HOST_FLAGS) -c $< -o $@

$(FW_HOST_DIR)/node_clock.o: bridge/node_clock.c bridge/node_clock.h
	@mkdir -p $(@D)
	$(CC) $(FW_HOST_FLAGS) -c $< -o $@

$(FW_HOST_DIR)/beaconloc_can.o: $(FW_HOST_CAN)/beaconloc_can.c $(FW_HOST_CAN)/beaconloc_can.h
	@mkdir -p $(@D)
	$(CC) $(FW_HOST_FLAGS) -c $< -o $@

$(FW_HOST_BIN): $(FW_HOST_DIR)/main.o $(FW_HOST_DIR)/board_log.o $(FW_HOST_DIR)/node_clock.o \
                $(FW_HOST_DIR)/beaconloc_can.o $(BUILD)/lib/float/libbeaconloc.a
	$(CC) -o $@ $^ -lm

.PHONY: bench-firmware
bench-firmware: $(FW_HOST_BIN) $(BUILD)/bridge/beaconloc-bridge | $(SETUP_STAMP)
	$(PY) tests/bench/firmware.py --firmware $(FW_HOST_BIN) --bridge $(BUILD)/bridge/beaconloc-bridge \
	    --out $(BUILD)/bench/firmware

TEST_BUILDS += $(FW_HOST_BIN)
