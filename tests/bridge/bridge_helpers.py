"""Helpers of the bridge's pytest suite (a uniquely named module, so that
other suites' conftest.py files cannot shadow it)."""
import os
import shutil
import socket
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
# The build folder: $BL_BUILD (make test-bridge-py passes its BUILD), else build/.
BUILD = Path(os.environ.get("BL_BUILD", REPO / "build"))
BRIDGE = BUILD / "bridge" / "beaconloc-bridge"
SITE = REPO / "hw_sim" / "beaconloc_sim" / "data" / "scenarios" / "kleeman-lab.ini"
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


def kernel_stamped_listener(port: int):
    """The integration suite's MAVLink listener (tests/integration/harness.py
    MavlinkListener) on udpin:127.0.0.1:port: every message with its datagram's
    kernel receive time, so a stall of the test process is not taken for one of
    the daemon. Imported here when first asked for, so that only the tests that
    use it load the harness."""
    sys.path.insert(0, str(REPO / "tests" / "integration"))
    from harness import MavlinkListener
    return MavlinkListener(port)


def kidnap_scenario(out_dir: Path, site: str, cut_s: int | None = None) -> Path:
    """The built-in scenario of `site` (hall, big-site, ...) carried 2 m at 60 s, its encoders silent
    around it: a scenario file in out_dir, its site the repository's. cut_s: the scenario's own
    duration_s set so (the simulator then draws other noise than the 120 s runs); None keeps it."""
    scenario = out_dir / f"{site}-kidnap{cut_s or ''}.scenario.ini"
    text = (SITE.parent / f"{site}.scenario.ini").read_text()
    assert "[faults]" not in text and f"site = {site}.ini" in text and "duration_s = 120" in text
    text = text.replace(f"site = {site}.ini", f"site = {SITE.parent / f'{site}.ini'}")
    if cut_s is not None:
        text = text.replace("duration_s = 120", f"duration_s = {cut_s}")
    scenario.write_text(text + "[faults]\nencoder_silence = 59.5, 1.0\nkidnap = 60, 0.0, 2.0\n")
    return scenario


def run_sim(out_dir: Path, scenario: str, duration_s: float, seed=None, sim_args=()):
    """Simulate a scenario into a candump log (sim_args: more options of `run`, e.g. --set);
    returns (log, truth CSV)."""
    name = Path(scenario).name.replace(".scenario.ini", "")  # name or path
    log = out_dir / f"{name}.log"
    truth = out_dir / f"{name}.truth.csv"
    cmd = sim_command() + ["run", scenario, "--log", str(log), "--truth", str(truth),
                           "--duration", str(duration_s)]
    if seed is not None:
        cmd += ["--seed", str(seed)]
    cmd += list(sim_args)
    subprocess.run(cmd, check=True, capture_output=True, timeout=300)
    return log, truth


def free_udp_port():
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def mavlink_listener(port):
    """pymavlink UDP listener with a large receive buffer."""
    from pymavlink import mavutil
    from beaconloc_sim.udp import widen_receive_buffer
    conn = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", source_system=255)
    widen_receive_buffer(conn.port)
    return conn
