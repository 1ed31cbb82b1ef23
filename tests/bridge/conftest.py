"""Fixtures for the bridge's pytest suite: the real daemon binary, simulator
logs (beaconloc-sim), MAVLink receivers (pymavlink), free UDP ports."""
import os
import shutil
import socket
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
BRIDGE = REPO / "build" / "bridge" / "beaconloc-bridge"
SITE = REPO / "hw_sim" / "scenarios" / "kleeman-lab.ini"
# Log timestamps are this epoch + simulated time (hw_sim scenario default
# [output] log_epoch_s, not overridden by the scenarios used here).
LOG_EPOCH_S = 1_700_000_000.0


def sim_command():
    exe = Path(sys.executable).with_name("beaconloc-sim")
    if exe.exists():
        return [str(exe)]
    found = shutil.which("beaconloc-sim")
    if found:
        return [found]
    return [sys.executable, "-m", "beaconloc_sim.cli"]


@pytest.fixture(scope="session")
def bridge_bin():
    if not BRIDGE.exists():
        pytest.fail(f"{BRIDGE} not built (make build/bridge/beaconloc-bridge)")
    return BRIDGE


def run_sim(out_dir: Path, scenario: str, duration_s: float, seed=None):
    log = out_dir / f"{scenario}.log"
    truth = out_dir / f"{scenario}.truth.csv"
    cmd = sim_command() + ["run", scenario, "--log", str(log), "--truth", str(truth),
                           "--duration", str(duration_s)]
    if seed is not None:
        cmd += ["--seed", str(seed)]
    subprocess.run(cmd, check=True, capture_output=True, timeout=300)
    return log, truth


@pytest.fixture(scope="session")
def kleeman_log(tmp_path_factory):
    """A 60 s kleeman-lab run: (log path, truth path)."""
    return run_sim(tmp_path_factory.mktemp("sim"), "kleeman-lab", 60)


def free_udp_port():
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture
def udp_port():
    return free_udp_port()


def mavlink_listener(port):
    """pymavlink UDP listener with a large receive buffer."""
    from pymavlink import mavutil
    conn = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", source_system=255)
    try:
        conn.port.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 8 << 20)
    except OSError:
        pass
    return conn
