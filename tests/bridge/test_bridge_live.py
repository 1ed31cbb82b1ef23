"""The daemon's live path on this CAN-less kernel: an LD_PRELOAD shim
(tests/bridge/fake_can_preload.c) answers socket(PF_CAN) with a UNIX
SOCK_SEQPACKET socket fed by this test with struct can_frame records in
real time from a simulator log, so the epoll loop, the CAN handler, kernel
receive timestamps (SO_TIMESTAMP), timerfd output, the missing-interface
retry and SIGTERM run as on a bus. The real bus is exercised by the
integration suite (tests/integration, in a VM with vcan)."""
import json
import signal
import socket
import struct
import subprocess
import time

import numpy as np
import pytest

from bridge_helpers import BRIDGE, SITE, kernel_stamped_listener

SHIM = BRIDGE.parents[1] / "tests" / "bridge" / "fake_can_preload.so"
FEED_S = 12.0
ERR_CRTL = 0x20000004  # CAN_ERR_FLAG | CAN_ERR_CRTL


def log_frames(log, seconds):
    out = []
    for line in open(log):
        ts, _, frame = line.split()[:3]
        t = float(ts[1:-1])
        if out and t - out[0][0] > seconds:
            break
        fid, data = frame.split("#")
        out.append((t, int(fid, 16), bytes.fromhex(data)))
    return out


def test_live_path_with_fake_can(bridge_bin, kleeman_log, tmp_path, udp_port):
    if not SHIM.exists():
        pytest.fail(f"{SHIM} not built (make test-bridge-py builds it)")
    log, truth_path = kleeman_log
    frames = log_frames(log, FEED_S)
    sock_path = tmp_path / "can.sock"
    stats_path, est_path = tmp_path / "stats.json", tmp_path / "est.csv"
    rec_path = tmp_path / "rec.log"
    listener = kernel_stamped_listener(udp_port)
    env = {"LD_PRELOAD": str(SHIM), "FAKE_CAN_SOCKET": str(sock_path), "PATH": "/usr/bin:/bin"}
    # started before the "interface" exists: not fatal, retried every second
    proc = subprocess.Popen([str(bridge_bin), "--site", str(SITE), "--can", "fake0",
                             "--mavlink", f"udpout:127.0.0.1:{udp_port}",
                             "--stats", str(stats_path), "--estimates", str(est_path),
                             "--record", str(rec_path),
                             "--status-interval", "2"],
                            stderr=subprocess.PIPE, text=True, env=env)
    try:
        time.sleep(1.5)
        assert proc.poll() is None
        srv = socket.socket(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        srv.bind(str(sock_path))
        srv.listen(1)
        srv.settimeout(5)
        can, _ = srv.accept()
        start = time.monotonic()
        t0 = frames[0][0]
        for i, (t, fid, data) in enumerate(frames):
            delay = start + (t - t0) - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            # struct can_frame: can_id u32, len u8, 3 pad bytes, data[8]
            can.send(struct.pack("<IB3x8s", fid, len(data), data.ljust(8, b"\0")))
            if i == len(frames) // 2:  # one error frame: controller problem, RX warning
                can.send(struct.pack("<IB3x8s", ERR_CRTL, 8, bytes([0, 0x04]) + bytes(6)))
        time.sleep(0.5)
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
        listener.close()
    assert proc.returncode == 0, err
    assert "fake0:" in err and "retrying every second" in err
    assert "fake0: up again" in err
    assert "final:" in err
    stats = json.loads(stats_path.read_text())
    # every frame sent arrived and was decoded; the error frame is read,
    # counted and recorded like any frame (as in replay)
    assert stats["frames_total"] == len(frames) + 1
    assert sum(stats["frames_received"].values()) == len(frames)
    assert stats["error_frames"] == 1 and stats["controller_errors"] == 1
    assert stats["lost_by_counter"] == 0
    recorded = rec_path.read_text().splitlines()
    assert len(recorded) == len(frames) + 1
    assert sum(" 20000004#0004000000000000" in ln for ln in recorded) == 1
    assert "fake0: error frame (class 0x4)" in err
    assert stats["latency_samples"] > 100
    assert 0 <= stats["latency_p50_us"] <= stats["latency_p99_us"]
    # ODOMETRY at the configured 30 Hz: one message per slot of the period's
    # grid at most, and nearly every slot. time_usec is the time of the newest
    # measurement in the estimate, so the intervals are quantised by the
    # sensor frames (quiet host: 30, 33, 35, 36, 40 ms; a median of 30 ms
    # failed a CI run). Never faster: over the whole run that quantisation is
    # one frame interval at most, so the mean rate over all intervals is at
    # most 30 Hz within 1 %, whatever the load (the mean over the intervals
    # under 1.5 periods, bounded above before, is biased upward under load: a
    # late measurement shortens one interval and lengthens the next past the
    # cut; 31.9 Hz beside a compiler). Not slower: a starved host delays some
    # ticks by a whole period (a busy loop beside it made the mean rate over
    # all intervals 28.49 Hz; a CPU-bound job at a higher priority than the
    # test batch 22.3 Hz), so the rate is taken over the intervals on the grid
    # (under 1.5 periods) and the others are counted apart and bounded.
    odo = [r.msg for r in listener.messages("ODOMETRY")]
    assert len(odo) > 100
    t = np.array([m.time_usec for m in odo], dtype=np.int64)
    dt_us = np.diff(t)
    assert np.all(dt_us > 0)
    period_us = 1e6 / 30.0
    assert 1e6 * len(dt_us) / float(t[-1] - t[0]) <= 30.3
    on_grid = dt_us[dt_us < 1.5 * period_us]
    assert 1e6 * len(on_grid) / float(np.sum(on_grid)) >= 28.5
    assert len(on_grid) >= 0.9 * len(dt_us), np.sort(dt_us)[-20:]
    hb = [r.msg for r in listener.messages("HEARTBEAT")]
    assert any(m.system_status == 5 for m in hb)  # CRITICAL while no CAN
    assert hb[-1].system_status in (3, 4)         # STANDBY / ACTIVE with CAN
    # the estimate on the receiver-node clock matches the truth
    truth = np.genfromtxt(truth_path, delimiter=",", names=True)
    est = np.genfromtxt(est_path, delimiter=",", names=True)
    last = est[-50:]
    xt = np.interp(last["t_us"], truth["t_us"], truth["x_m"])
    yt = np.interp(last["t_us"], truth["t_us"], truth["y_m"])
    err_m = np.hypot(last["x_m"] - xt, last["y_m"] - yt)
    assert np.max(err_m) < 0.1, err_m.max()
    print(f"live (fake CAN) latency p50 {stats['latency_p50_us']} us "
          f"p99 {stats['latency_p99_us']} us over {stats['latency_samples']} sends")
