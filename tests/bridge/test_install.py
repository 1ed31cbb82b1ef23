"""make install, as an operator or a packager runs it (issue 15): into a
DESTDIR, with the default PREFIX and with PREFIX=/usr. The installed daemon
runs; the unit passes `systemd-analyze verify` and its exposure score is the
one docs/bridge.md quotes; the manual page renders without a groff warning;
an operator's site.ini is never overwritten; and every system call the
daemon makes on its live path (epoll loop, CAN socket, timers, signals,
SIGHUP reload, stats, estimates, record, SIGTERM) is allowed by the unit's
SystemCallFilter, so the sandbox cannot break the daemon in the field."""
import os
import re
import shutil
import signal
import socket
import struct
import subprocess
import time
from pathlib import Path

import pytest

from bridge_helpers import BRIDGE, SITE

REPO = Path(__file__).resolve().parents[2]
BUILD = BRIDGE.parents[1]
SHIM = BUILD / "tests" / "bridge" / "fake_can_preload.so"
SITES = ["kleeman-lab.ini", "eurobot.ini", "marvelmind.ini", "millibots-room.ini"]


def make_install(destdir: Path, *extra: str) -> subprocess.CompletedProcess:
    return subprocess.run(["make", "-s", "-C", str(REPO), f"BUILD={BUILD}", "install",
                           f"DESTDIR={destdir}", *extra],
                          check=True, capture_output=True, text=True)


def unit_value(unit_text: str, key: str) -> list[str]:
    return [line.split("=", 1)[1] for line in unit_text.splitlines()
            if line.startswith(key + "=")]


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    dest = tmp_path_factory.mktemp("destdir")
    make_install(dest)
    return dest


def test_install_lays_out_every_file(installed):
    d = installed
    binary = d / "usr/local/bin/beaconloc-bridge"
    unit = d / "usr/local/lib/systemd/system/beaconloc-bridge.service"
    man = d / "usr/local/share/man/man8/beaconloc-bridge.8"
    assert binary.stat().st_mode & 0o777 == 0o755
    for f in [unit, man, d / "usr/local/share/beaconloc/beaconloc.dbc", d / "etc/beaconloc/site.ini"]:
        assert f.stat().st_mode & 0o777 == 0o644, f
    for s in SITES:
        assert (d / "usr/local/share/beaconloc/sites" / s).read_bytes() == \
            (REPO / "hw_sim/beaconloc_sim/data/scenarios" / s).read_bytes()
    assert (d / "etc/beaconloc/site.ini").read_bytes() == \
        (REPO / "hw_sim/beaconloc_sim/data/scenarios/kleeman-lab.ini").read_bytes()
    # nothing outside DESTDIR's usr/local and etc
    tops = {p.relative_to(d).parts[:2] for p in d.rglob("*") if p.is_file()}
    assert tops <= {("usr", "local"), ("etc", "beaconloc")}
    out = subprocess.run([str(binary), "--version"], check=True, capture_output=True, text=True)
    assert out.stdout.startswith("beaconloc-bridge ")
    # the installed daemon reads the installed site file (a config check: a replay of nothing)
    empty = d / "empty.log"
    empty.write_text("")
    run = subprocess.run([str(binary), "--site", str(d / "etc/beaconloc/site.ini"),
                          "--replay", str(empty)], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    text = unit.read_text()
    assert unit_value(text, "ExecStart")[0].split()[:3] == [
        "/usr/local/bin/beaconloc-bridge", "--site", "/etc/beaconloc/site.ini"]


def test_prefix_usr_and_an_operators_site_file_kept(tmp_path):
    (tmp_path / "etc/beaconloc").mkdir(parents=True)
    mine = tmp_path / "etc/beaconloc/site.ini"
    mine.write_text("; the operator's own site\n")
    out = make_install(tmp_path, "PREFIX=/usr")
    assert "site.ini exists: kept" in out.stdout
    assert mine.read_text() == "; the operator's own site\n"
    unit = (tmp_path / "usr/lib/systemd/system/beaconloc-bridge.service").read_text()
    assert unit_value(unit, "ExecStart")[0].startswith("/usr/bin/beaconloc-bridge --site "
                                                       "/etc/beaconloc/site.ini")
    assert (tmp_path / "usr/bin/beaconloc-bridge").is_file()
    assert (tmp_path / "usr/share/man/man8/beaconloc-bridge.8").is_file()


def test_unit_verifies_and_its_exposure_is_the_documented_one(installed, tmp_path):
    if not shutil.which("systemd-analyze"):
        pytest.fail("systemd-analyze missing (make setup installs systemd)")
    unit = (installed / "usr/local/lib/systemd/system/beaconloc-bridge.service").read_text()
    # verify checks that ExecStart exists and that man:beaconloc-bridge(8) resolves:
    # point both at the DESTDIR
    staged = tmp_path / "beaconloc-bridge.service"
    staged.write_text(unit.replace("ExecStart=/usr/local/bin/",
                                   f"ExecStart={installed}/usr/local/bin/"))
    env = dict(os.environ, MANPATH=str(installed / "usr/local/share/man"))
    v = subprocess.run(["systemd-analyze", "verify", str(staged)], capture_output=True,
                       text=True, env=env)
    assert v.returncode == 0 and v.stderr.strip() == "", v.stderr
    sec = subprocess.run(["systemd-analyze", "security", "--offline=true", str(staged)],
                         capture_output=True, text=True, env=env)
    m = re.search(r"Overall exposure level for beaconloc-bridge.service: (\d+\.\d) (\w+)",
                  sec.stdout)
    assert m, sec.stdout[-500:]
    documented = re.search(r"`systemd-analyze security` exposure (\d+\.\d) \((\w+)\)",
                           (REPO / "docs/bridge.md").read_text())
    assert documented, "docs/bridge.md quotes no systemd-analyze security score"
    assert (m.group(1), m.group(2)) == documented.groups()
    assert float(m.group(1)) <= 3.0        # hardened: systemd's "OK" band or better


def test_manual_page_renders_without_warnings(installed):
    man = installed / "usr/local/share/man/man8/beaconloc-bridge.8"
    text = man.read_text()
    assert ".\\\" Automatically generated by Pandoc" in text.splitlines()[1]
    for section in ["NAME", "SYNOPSIS", "DESCRIPTION", "OPTIONS", "CONFIGURATION", "SIGNALS",
                    "EXIT STATUS", "FILES", "SEE ALSO"]:
        assert f'.SH {section}\n' in text or f'.SH "{section}"\n' in text, section
    r = subprocess.run(["groff", "-man", "-Tutf8", "-ww", "-rLL=200n", "-z", str(man)],
                       capture_output=True, text=True)
    assert r.returncode == 0 and r.stderr == "", r.stderr


def _expand(group: str, seen: set) -> set:
    """The system calls of a systemd syscall group, nested groups expanded."""
    if group in seen:
        return set()
    seen.add(group)
    out = subprocess.run(["systemd-analyze", "syscall-filter", group], check=True,
                         capture_output=True, text=True).stdout
    calls = set()
    for line in out.splitlines()[1:]:
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        calls |= _expand(line, seen) if line.startswith("@") else {line}
    return calls


def test_every_system_call_of_the_live_daemon_passes_the_units_filter(
        installed, kleeman_log, tmp_path, udp_port):
    if not SHIM.exists():
        pytest.fail(f"{SHIM} not built (make test-bridge-py builds it)")
    if not shutil.which("strace"):
        pytest.fail("strace missing (make setup installs it)")
    unit = (installed / "usr/local/lib/systemd/system/beaconloc-bridge.service").read_text()
    allowed, denied = set(), set()
    for value in unit_value(unit, "SystemCallFilter"):
        deny = value.startswith("~")
        for item in value.lstrip("~").split():
            calls = _expand(item, set()) if item.startswith("@") else {item}
            (denied if deny else allowed).update(calls)
    allowed -= denied
    assert {"epoll_wait", "recvmsg", "sendto", "timerfd_settime"} <= allowed
    assert {"sched_setscheduler", "setrlimit", "reboot"} <= denied   # the filter is not everything

    log, _ = kleeman_log
    frames = []
    for line in open(log):
        ts, _, frame = line.split()[:3]
        fid, data = frame.split("#")
        frames.append((float(ts[1:-1]), int(fid, 16), bytes.fromhex(data)))
        if frames[-1][0] - frames[0][0] > 4.0:
            break
    sock_path, trace = tmp_path / "can.sock", tmp_path / "strace.txt"
    srv = socket.socket(socket.AF_UNIX, socket.SOCK_SEQPACKET)
    srv.bind(str(sock_path))
    srv.listen(1)
    srv.settimeout(10)
    env = {"LD_PRELOAD": str(SHIM), "FAKE_CAN_SOCKET": str(sock_path), "PATH": "/usr/bin:/bin"}
    proc = subprocess.Popen(["strace", "-f", "-qq", "-o", str(trace),
                             str(installed / "usr/local/bin/beaconloc-bridge"),
                             "--site", str(SITE), "--can", "fake0",
                             "--mavlink", f"udpout:127.0.0.1:{udp_port}",
                             "--stats", str(tmp_path / "stats.json"),
                             "--estimates", str(tmp_path / "est.csv"),
                             "--record", str(tmp_path / "rec.log"), "--status-interval", "1"],
                            stderr=subprocess.DEVNULL, env=env)
    daemon = None
    try:
        can, _ = srv.accept()
        # strace ignores SIGHUP and SIGTERM while it runs a command: signal the daemon
        daemon = int(Path(f"/proc/{proc.pid}/task/{proc.pid}/children").read_text().split()[0])
        start, t0 = time.monotonic(), frames[0][0]
        for i, (t, fid, data) in enumerate(frames):
            delay = start + (t - t0) - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            can.send(struct.pack("<IB3x8s", fid, len(data), data.ljust(8, b"\0")))
            if i == len(frames) // 2:
                os.kill(daemon, signal.SIGHUP)           # reload the site file
        time.sleep(1.5)                                  # housekeeping, status line
        os.kill(daemon, signal.SIGTERM)
        assert proc.wait(timeout=10) == 0         # strace exits with the daemon's status
    finally:
        if proc.poll() is None:                   # a failure above: leave nothing running
            if daemon is not None:
                try:
                    os.kill(daemon, signal.SIGKILL)
                except ProcessLookupError:
                    pass
            proc.kill()
            proc.wait()
    made = set()
    for line in trace.read_text().splitlines():   # "PID name(args) = result"
        m = re.match(r"(?:\d+\s+)?([a-z_0-9]+)\(", line)
        if m:
            made.add(m.group(1))
    # the real CAN path also binds the socket, sets CAN_RAW filters and asks the
    # interface index: calls the shim answers without the kernel
    made |= {"bind", "setsockopt", "ioctl"}
    assert {"epoll_wait", "recvmsg", "timerfd_settime", "sendto", "rt_sigprocmask"} <= made, made
    assert made - allowed == set(), f"system calls the unit's filter refuses: {made - allowed}"
