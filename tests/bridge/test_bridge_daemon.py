"""The real beaconloc-bridge binary as a daemon: bad configuration exits 78
naming file, line and key; a missing CAN interface is not fatal; HEARTBEAT
and TIMESYNC over UDP; SIGUSR1 reports; SIGHUP reloads (keeping or re-initialising the
filter, refusing a bad file); SIGTERM exits cleanly with a final status line
and the --stats JSON."""
import json
import re
import signal
import subprocess
import time

import pytest
from pymavlink import mavutil

from bridge_helpers import SITE, mavlink_listener

MAV = mavutil.mavlink


def run(bridge_bin, *args, timeout=20):
    return subprocess.run([str(bridge_bin), *args], capture_output=True, text=True,
                          timeout=timeout)


def site_with(tmp_path, name, replace=None, append=""):
    text = SITE.read_text()
    if replace:
        old, new = replace
        assert old in text
        text = text.replace(old, new, 1)
    p = tmp_path / name
    p.write_text(text + append)
    return p


def line_of(path, needle):
    for i, line in enumerate(path.read_text().splitlines(), 1):
        if line.startswith(needle):
            return i
    raise AssertionError(needle)


def test_bad_site_exits_78_naming_file_line_key(bridge_bin, tmp_path):
    bad = site_with(tmp_path, "typo.ini", replace=("gate_sigma = 3.0", "gate_sigmaa = 3.0"))
    p = run(bridge_bin, "--site", str(bad), "--replay", "/dev/null")
    assert p.returncode == 78
    n = line_of(bad, "gate_sigmaa")
    assert f"{bad}:{n}: [noise] gate_sigmaa: unknown key" in p.stderr

    bad = site_with(tmp_path, "nan.ini", replace=("x_m = 11.95", "x_m = eleven"))
    p = run(bridge_bin, "--site", str(bad), "--replay", "/dev/null")
    assert p.returncode == 78
    n = line_of(bad, "x_m = eleven")
    assert f"{bad}:{n}: [beacon4] x_m: not a number: 'eleven'" in p.stderr

    # a misspelt section would drop its keys silently
    bad = site_with(tmp_path, "section.ini", replace=("[bridge]", "[bridg]"))
    p = run(bridge_bin, "--site", str(bad), "--replay", "/dev/null")
    assert p.returncode == 78
    n = line_of(bad, "[bridg]")
    assert f"{bad}:{n}: [bridg] unknown section" in p.stderr


def test_estimator_rejects_geometry_exit_78(bridge_bin, tmp_path):
    # three beacons on one line: the library's config check refuses it and
    # the message still names the site file's key
    text = SITE.read_text()
    text = text.replace("count = 6", "count = 3", 1)
    lines, out, sec = text.splitlines(), [], None
    for line in lines:
        m = re.match(r"\[(\w+)\]", line)
        if m:
            sec = m.group(1)
        if sec in ("beacon4", "beacon5", "beacon6"):
            continue
        if sec in ("beacon1", "beacon2", "beacon3") and line.startswith(("x_m", "y_m")):
            line = f"{line[:3]} = {float(sec[-1])}"  # beacon k at (k, k)
        out.append(line)
    p = tmp_path / "collinear.ini"
    p.write_text("\n".join(out) + "\n")
    r = run(bridge_bin, "--site", str(p), "--replay", "/dev/null")
    assert r.returncode == 78, r.stderr
    assert str(p) in r.stderr and "rejected by the estimator" in r.stderr


def test_command_line_errors(bridge_bin, tmp_path):
    p = run(bridge_bin, "--site", str(SITE), "--rate", "abc", "--replay", "/dev/null")
    assert p.returncode == 78 and "--rate: 'abc' is not a number" in p.stderr
    p = run(bridge_bin, "--site", str(SITE), "--mavlink", "tcp:x:1", "--replay", "/dev/null")
    assert p.returncode == 78 and "--mavlink: 'tcp:x:1'" in p.stderr
    p = run(bridge_bin, "--replay", "/dev/null")  # no site: no beacons
    assert p.returncode == 78 and "--site" in p.stderr
    p = run(bridge_bin, "--bogus")
    assert p.returncode == 64
    p = run(bridge_bin, "--site", str(SITE), "--replay", str(tmp_path / "missing.log"))
    assert p.returncode == 66 and "missing.log" in p.stderr


@pytest.fixture
def live_bridge(bridge_bin, tmp_path, udp_port):
    """The daemon on a CAN interface that does not exist, MAVLink to us."""
    site = site_with(tmp_path, "site.ini")
    stats = tmp_path / "stats.json"
    conn = mavlink_listener(udp_port)
    proc = subprocess.Popen([str(bridge_bin), "--site", str(site), "--can", "blnocan0",
                             "--mavlink", f"udpout:127.0.0.1:{udp_port}",
                             "--stats", str(stats), "--status-interval", "1"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    yield dict(proc=proc, conn=conn, site=site, stats=stats)
    if proc.poll() is None:
        proc.kill()
        proc.wait()
    conn.close()


def wait_msg(conn, mtype, timeout=5.0, cond=lambda m: True):
    end = time.time() + timeout
    while time.time() < end:
        m = conn.recv_match(type=mtype, blocking=True, timeout=0.5)
        if m is not None and cond(m):
            return m
    return None


def test_missing_can_not_fatal_heartbeat_timesync_sigterm(live_bridge):
    proc, conn = live_bridge["proc"], live_bridge["conn"]
    hb = wait_msg(conn, "HEARTBEAT")
    assert hb is not None, "no HEARTBEAT"
    assert hb.type == MAV.MAV_TYPE_ONBOARD_CONTROLLER
    assert hb.autopilot == MAV.MAV_AUTOPILOT_INVALID
    assert hb.system_status == MAV.MAV_STATE_CRITICAL  # no CAN
    assert hb.get_srcComponent() == 197
    # TIMESYNC request (tc1 = 0) is answered with our ts1 echoed
    conn.mav.timesync_send(0, 123456789)
    ts = wait_msg(conn, "TIMESYNC", cond=lambda m: m.ts1 == 123456789)
    assert ts is not None and ts.tc1 > 0
    time.sleep(2.5)  # a few retries
    assert proc.poll() is None, "daemon exited without CAN"
    # SIGUSR1: statistics written now, the daemon keeps running
    assert not live_bridge["stats"].exists()
    proc.send_signal(signal.SIGUSR1)
    time.sleep(0.5)
    assert proc.poll() is None
    early = json.loads(live_bridge["stats"].read_text())
    assert early["heartbeat_sent"] >= 2
    proc.send_signal(signal.SIGTERM)
    out, err = proc.communicate(timeout=10)
    assert proc.returncode == 0, err
    # the missing interface is logged once, not once per retry
    assert err.count("blnocan0:") >= 1
    assert len(re.findall(r"blnocan0: .*retrying every second", err)) == 1
    assert "final:" in err
    stats = json.loads(live_bridge["stats"].read_text())
    assert stats["frames_total"] == 0
    assert stats["heartbeat_sent"] >= 2
    assert stats["timesync_answered"] >= 1


def test_sighup_reload(live_bridge):
    proc, site = live_bridge["proc"], live_bridge["site"]
    assert wait_msg(live_bridge["conn"], "HEARTBEAT") is not None
    # tuning only: filter kept
    site.write_text(site.read_text().replace("gate_sigma = 3.0", "gate_sigma = 4.0"))
    proc.send_signal(signal.SIGHUP)
    time.sleep(0.5)
    # geometry: re-initialised
    site.write_text(site.read_text().replace("x_m = 11.95", "x_m = 11.90"))
    proc.send_signal(signal.SIGHUP)
    time.sleep(0.5)
    # a broken file: refused, the daemon keeps running
    good = site.read_text()
    site.write_text(good + "\n[noise]\nbogus = 1\n")
    proc.send_signal(signal.SIGHUP)
    time.sleep(0.5)
    assert proc.poll() is None
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=10)
    assert proc.returncode == 0, err
    assert "geometry unchanged, filter kept" in err
    assert "geometry changed, estimator re-initialised" in err
    assert "[noise] bogus: unknown key" in err and "not reloaded" in err
