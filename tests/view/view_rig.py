"""Starting beaconloc-view and a paced bridge replay for the view's test and `make fig-view`."""
from __future__ import annotations

import os
import subprocess
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
VIEW = REPO / ".venv" / "bin" / "beaconloc-view"
BUILD = Path(os.environ.get("BL_BUILD", REPO / "build"))
BRIDGE = BUILD / "bridge" / "beaconloc-bridge"
SITE = REPO / "hw_sim" / "beaconloc_sim" / "data" / "scenarios" / "kleeman-lab.ini"


def start_view(tmp: Path, scenario: str, udp_port: int, timeout_s: float = 30.0):
    """beaconloc-view on udpin:127.0.0.1:udp_port, HTTP on a free port; (process, URL)."""
    url_file = tmp / "view.url"
    out = tmp / "view.out"
    proc = subprocess.Popen([str(VIEW), "--scenario", scenario, "--mavlink",
                             f"udpin:127.0.0.1:{udp_port}", "--port", "0", "--url-file",
                             str(url_file)], stdout=out.open("w"), stderr=subprocess.STDOUT)
    deadline = time.monotonic() + timeout_s
    while not url_file.exists() and time.monotonic() < deadline and proc.poll() is None:
        time.sleep(0.1)
    if not url_file.exists():
        proc.kill()
        proc.wait()
        raise RuntimeError(f"beaconloc-view did not start: {out.read_text()}")
    return proc, url_file.read_text().strip()


def start_replay(tmp: Path, log: Path, speed: float, udp_ports: list[int]) -> subprocess.Popen:
    """The bridge replaying log paced at speed x, sending to every port."""
    argv = [str(BRIDGE), "--site", str(SITE), "--replay", str(log), "--speed", str(speed)]
    for p in udp_ports:
        argv += ["--mavlink", f"udpout:127.0.0.1:{p}"]
    return subprocess.Popen(argv, stdout=(tmp / "bridge.out").open("w"), stderr=subprocess.STDOUT)


def stop(proc: subprocess.Popen) -> None:
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
