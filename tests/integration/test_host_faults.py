"""Faults of the host under the daemon, on a live kernel CAN bus: nothing
that can block may run on the event loop (docs/bridge.md, "Host faults").

Beside the working endpoint the bridge has one whose name never resolves,
one whose name server answers only after 5 s (the test-only LD_PRELOAD shim
tests/bridge/slow_dns_preload.c), a serial endpoint on a pty whose other end
goes away mid-run (an unplugged adapter), and --record on a full disk
(/dev/full). ODOMETRY on the working endpoint keeps its rate, and no CAN
frame is lost. The same faults in paced replay, each on its own, are in
tests/bridge/test_bridge_hostfaults.py.
"""
from __future__ import annotations

import os
import select
import threading
import time

import pytest

import harness as h

RUN_S = 30.0
ODOMETRY_RATE_HZ = 30.0  # [bridge] odometry_rate_hz of kleeman-lab.ini
SLOW_DNS = h.BUILD / "tests" / "bridge" / "slow_dns_preload.so"


@pytest.mark.live_s(RUN_S)
def test_host_faults_on_a_live_bus(rig):
    assert SLOW_DNS.exists(), f"{SLOW_DNS} not built (make test-bridge-py builds it)"
    master, slave = os.openpty()
    tty = os.ttyname(slave)
    os.close(slave)
    serial_bytes = bytearray()
    stop = threading.Event()

    def read_serial():
        while not stop.is_set():
            if select.select([master], [], [], 0.05)[0]:
                try:
                    serial_bytes.extend(os.read(master, 4096))
                except OSError:  # no slave open (yet): the bridge opens it
                    time.sleep(0.02)

    reader = threading.Thread(target=read_serial, daemon=True)
    reader.start()
    marks = {}

    def unplug(r):
        stop.set()
        reader.join(2)
        marks["serial_bytes"] = len(serial_bytes)
        os.close(master)
        marks["unplugged"] = time.monotonic()

    run = h.run_live(
        rig, "kleeman-lab", RUN_S,
        bridge_extra=["--mavlink", "udpout:nonexistent.invalid:14550",
                      "--mavlink", "udpout:slow.beaconloc.test:14551",
                      "--mavlink", f"serial:{tty}:921600",
                      "--record", "/dev/full"],
        bridge_env={"LD_PRELOAD": str(SLOW_DNS), "SLOW_DNS_NAME": "slow.beaconloc.test",
                    "SLOW_DNS_DELAY_S": "5"},
        actions=[(12.0, unplug)])
    bridge = next(p for p in rig.procs if p.name == "bridge")
    err = h.tail(bridge.stderr_path, 20000)
    assert run.bridge_rc == 0, rig.logs()

    # The working endpoint: ODOMETRY at its rate, no gap, before and after the unplug.
    times = [x.t_mono_s for x in run.odometry
             if run.t_sim_start_mono_s + 2.0 <= x.t_mono_s <= run.t_sim_end_mono_s]
    rate = h.rate_hz(times)
    assert 0.9 * ODOMETRY_RATE_HZ <= rate <= 1.1 * ODOMETRY_RATE_HZ, f"ODOMETRY at {rate:.1f} Hz"
    gap = h.max_gap_s(times)
    assert gap < 0.5, f"ODOMETRY stopped for {gap:.2f} s"
    assert sum(t > marks["unplugged"] + 2.0 for t in times) > 5 * ODOMETRY_RATE_HZ

    # Every fault was met, and said once.
    assert marks["serial_bytes"] > 1000 and b"\xfd" in serial_bytes, "no MAVLink 2 on the serial port"
    assert "nonexistent.invalid" in err, err
    assert err.count("--record /dev/full: write failed: No space left on device") == 1, err
    assert run.bridge_stats["write_errors_per_file"]["record"] >= 1

    # No CAN frame lost.
    bs = run.bridge_stats
    sent = h.sim_frames_sent(run.sim_stats)
    received = sum(bs["frames_received_by_id"].values())
    assert sent > 1000
    assert received == sent - bs["dropped_by_kernel"], (
        f"sent {sent}, received {received}, kernel drops {bs['dropped_by_kernel']}")
    assert bs["dropped_by_kernel"] == 0 and bs["lost_by_counter"] == 0
