"""The bridge as a MAVLink component, with a real pymavlink client over UDP
against the daemon replaying a simulated kleeman-lab log (docs/mavlink.md,
"Parameters", "Commands", "Who may change what"): the parameter list (count,
indices, the site file's values), reads by name and index, a PARAM_SET in
range applied (the pulse gate: rejections appear), one out of range refused
with the value unchanged, the override file kept across a restart, commands
to our component answered (REQUEST_MESSAGE, the re-initialisation that bumps
ODOMETRY's reset_counter, UNSUPPORTED), nothing answered for another
component, system ids outside control_sysids refused, and MAVLink 2 signing
(signed accepted, unsigned refused, a wrong key dropped and counted, a key
file others can read refused at start)."""
import configparser
import hashlib
import json
import os
import signal
import subprocess
import time

import pytest
from pymavlink import mavutil

from beaconloc_sim.site_schema import load_schema
from bridge_helpers import SITE, mavlink_listener

MAV = mavutil.mavlink
PARAMS = load_schema().params()
ODOMETRY_ID, GPS_RAW_INT_ID = 331, 24  # MAVLink 2 message ids (common.xml)


class Bridge:
    """The daemon replaying `log` at `speed` x, its MAVLink to a pymavlink
    client (system `client_sysid`), a --stats file refreshed by SIGUSR1."""

    def __init__(self, bridge_bin, log, tmp_path, port, extra_site="", speed=1.0,
                 client_sysid=255, key=None):
        self.site = tmp_path / "site.ini"
        self.param_file = tmp_path / "params.ini"
        self.stats_path = tmp_path / "stats.json"
        text = SITE.read_text() + f"\nparam_file = {self.param_file}\n" + extra_site
        self.site.write_text(text)  # [bridge] is the site file's last section
        self.conn = mavlink_listener(port) if client_sysid == 255 else \
            mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", source_system=client_sysid)
        self.key = key
        self.proc = subprocess.Popen(
            [str(bridge_bin), "--site", str(self.site), "--replay", str(log), "--speed", str(speed),
             "--mavlink", f"udpout:127.0.0.1:{port}", "--stats", str(self.stats_path),
             "--status-interval", "0"], stderr=subprocess.PIPE, text=True)

    def start(self):
        """The first HEARTBEAT; with a key, the client signs from then on (pymavlink makes a new
        MAVLink object, without signing, when the first MAVLink 2 frame switches it over) and
        takes the next HEARTBEAT only with a good signature."""
        if self.wait_type("HEARTBEAT", 5.0) is None:
            return False
        if self.key is not None:
            self.conn.setup_signing(self.key, sign_outgoing=True)
            if self.wait_type("HEARTBEAT", 2.0) is None or self.conn.mav.signing.goodsig_count < 1:
                return False
        return True

    def wait(self, pred, timeout=3.0):
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            m = self.conn.recv_match(blocking=True, timeout=0.2)
            if m is not None and pred(m):
                return m
        return None

    def wait_type(self, kind, timeout=3.0, **fields):
        return self.wait(lambda m: m.get_type() == kind and
                         all(getattr(m, k) == v for k, v in fields.items()), timeout)

    def stats(self):
        self.proc.send_signal(signal.SIGUSR1)
        time.sleep(0.3)
        return json.loads(self.stats_path.read_text())

    def param(self, name, timeout=2.0):
        self.conn.mav.param_request_read_send(1, 197, name.encode(), -1)
        return self.wait_type("PARAM_VALUE", timeout, param_id=name)

    def set(self, name, value, component=197):
        self.conn.mav.param_set_send(1, component, name.encode(), value,
                                     MAV.MAV_PARAM_TYPE_REAL32)
        return self.wait_type("PARAM_VALUE", 2.0, param_id=name)

    def command(self, cmd, *params, component=197, as_int=False):
        p = list(params) + [0.0] * (7 - len(params))
        if as_int:
            self.conn.mav.command_int_send(1, component, 0, cmd, 0, 0, p[0], p[1], p[2], p[3],
                                           int(p[4]), int(p[5]), p[6])
        else:
            self.conn.mav.command_long_send(1, component, cmd, 0, *p)
        return self.wait_type("COMMAND_ACK", 2.0, command=cmd)

    def stop(self):
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
        _, err = self.proc.communicate(timeout=15)
        self.conn.close()
        return err


@pytest.fixture
def bridge(bridge_bin, kleeman_log, tmp_path, udp_port):
    b = Bridge(bridge_bin, kleeman_log[0], tmp_path, udp_port)
    assert b.start()
    yield b
    err = b.stop()
    assert b.proc.returncode == 0, err


def site_value(section, key):
    cp = configparser.ConfigParser(inline_comment_prefixes=("#", ";"))
    cp.read(SITE)
    return float(cp[section][key]) if cp.has_option(section, key) else None


def test_param_list_count_index_and_values(bridge):
    bridge.conn.mav.param_request_list_send(1, 197)
    got = {}
    end = time.monotonic() + 5
    while time.monotonic() < end and len(got) < len(PARAMS):
        m = bridge.wait_type("PARAM_VALUE", 1.0)
        if m is not None:
            assert m.param_count == len(PARAMS)
            got[m.param_index] = m
    assert sorted(got) == list(range(len(PARAMS)))
    for i, k in enumerate(PARAMS):  # index order = the schema's order
        m = got[i]
        assert m.param_id == k.param
        assert m.param_type == (MAV.MAV_PARAM_TYPE_INT32 if k.type == "int"
                                else MAV.MAV_PARAM_TYPE_REAL32)
        given = site_value(k.section, k.name)
        expect = given if given is not None else k.default
        if k.param == "BR_STATUS_INT":
            expect = 0  # --status-interval 0: the command line over the site file
        assert m.param_value == pytest.approx(expect, rel=1e-6), k.param
    # read by name and by index
    assert bridge.param("BCN_PERIOD").param_index == 0
    bridge.conn.mav.param_request_read_send(1, 197, b"", 3)
    m = bridge.wait_type("PARAM_VALUE", 2.0, param_index=3)
    assert m is not None and m.param_id == PARAMS[3].param
    # a name we do not have: no answer (the protocol's way)
    bridge.conn.mav.param_request_read_send(1, 197, b"NO_SUCH_PARAM", -1)
    assert bridge.wait_type("PARAM_VALUE", 1.0) is None


def test_param_set_applies_refuses_and_is_saved(bridge):
    """NSE_GATE = [noise] gate_sigma: 0.05 sigma gates most pulses out (the filter kept, its
    state unchanged, until the persistent-rejection watch restarts it)."""
    time.sleep(3)
    a = bridge.stats()
    time.sleep(3)
    b = bridge.stats()
    before_ok = b["pulses_accepted"] - a["pulses_accepted"]
    before_rej = b["pulses_rejected"] - a["pulses_rejected"]
    assert before_ok > 50 and before_rej <= 0.05 * before_ok
    m = bridge.set("NSE_GATE", 0.05)
    assert m is not None and m.param_value == pytest.approx(0.05)
    assert "gate_sigma = 0.05\n" in bridge.param_file.read_text()
    a = bridge.stats()
    time.sleep(3)
    b = bridge.stats()
    after_ok = b["pulses_accepted"] - a["pulses_accepted"]
    after_rej = b["pulses_rejected"] - a["pulses_rejected"]
    assert after_rej >= 0.2 * (after_ok + after_rej), (after_ok, after_rej)
    # out of range (0, 1000]: refused, the value unchanged, the file too
    saved = bridge.param_file.read_text()
    m = bridge.set("NSE_GATE", 5000.0)
    assert m is not None and m.param_value == pytest.approx(0.05)
    assert bridge.param("NSE_GATE").param_value == pytest.approx(0.05)
    assert bridge.param_file.read_text() == saved
    # an INT32 that is not a whole number: refused too
    iters = bridge.param("TUN_IEKF_ITER").param_value
    assert bridge.set("TUN_IEKF_ITER", 2.5).param_value == iters
    c = bridge.stats()["mavlink_control"]
    assert c["params_set"] == 1 and c["params_refused"] == 2


def test_param_set_keeps_the_filter_unless_geometry(bridge):
    """Tuning (TUN_ACC_NOISE): the filter goes on, reset_counter unchanged; geometry
    (ROB_WHEEL_BASE): re-initialised as by SIGHUP, reset_counter up by one."""
    odo = bridge.wait(lambda m: m.get_type() == "ODOMETRY" and m.quality >= 0, 10.0)
    assert odo is not None
    before = odo.reset_counter
    assert bridge.set("TUN_ACC_NOISE", 0.6).param_value == pytest.approx(0.6)
    txt = bridge.wait_type("STATUSTEXT", 2.0)
    assert txt is not None and "TUN_ACC_NOISE = 0.6" in txt.text and "re-init" not in txt.text
    for _ in range(30):  # a second of ODOMETRY: the same filter
        m = bridge.wait_type("ODOMETRY", 1.0)
        assert m is not None and m.reset_counter == before
    assert bridge.set("ROB_WHEEL_BASE", 0.55).param_value == pytest.approx(0.55)
    txt = bridge.wait(lambda m: m.get_type() == "STATUSTEXT" and "ROB_WHEEL_BASE" in m.text, 2.0)
    assert txt is not None and "re-initialised" in txt.text
    after = bridge.wait(lambda m: m.get_type() == "ODOMETRY" and m.reset_counter != before, 10.0)
    assert after is not None and after.reset_counter == (before + 1) % 256


def test_override_file_survives_a_restart(bridge_bin, kleeman_log, tmp_path, udp_port):
    b = Bridge(bridge_bin, kleeman_log[0], tmp_path, udp_port)
    try:
        assert b.start()
        assert b.set("TUN_ACC_NOISE", 0.75).param_value == pytest.approx(0.75)
        assert b.set("TUN_IEKF_ITER", 6).param_value == 6
    finally:
        assert b.stop() is not None
    text = b.param_file.read_text()
    assert "[tuning]" in text and "accel_noise_mps2 = 0.75\n" in text
    assert "iekf_max_iterations = 6\n" in text
    b = Bridge(bridge_bin, kleeman_log[0], tmp_path, udp_port)
    try:
        assert b.start()
        assert b.param("TUN_ACC_NOISE").param_value == pytest.approx(0.75)
        assert b.param("TUN_IEKF_ITER").param_value == 6
        assert b.param("NSE_GATE").param_value == pytest.approx(site_value("noise", "gate_sigma"))
    finally:
        err = b.stop()
    assert b.proc.returncode == 0, err


def test_commands_to_our_component(bridge):
    odo = bridge.wait(lambda m: m.get_type() == "ODOMETRY" and m.quality >= 0, 10.0)
    assert odo is not None
    # REQUEST_MESSAGE: ACK, then the message (COMMAND_LONG and COMMAND_INT)
    ack = bridge.command(MAV.MAV_CMD_REQUEST_MESSAGE, 0)
    assert ack is not None and ack.result == MAV.MAV_RESULT_ACCEPTED
    assert bridge.wait_type("HEARTBEAT", 1.0) is not None
    ack = bridge.command(MAV.MAV_CMD_REQUEST_MESSAGE, ODOMETRY_ID, as_int=True)
    assert ack is not None and ack.result == MAV.MAV_RESULT_ACCEPTED
    assert bridge.wait_type("ODOMETRY", 1.0) is not None
    ack = bridge.command(MAV.MAV_CMD_REQUEST_MESSAGE, 22, 5)  # PARAM_VALUE, param2 its index
    assert ack is not None and ack.result == MAV.MAV_RESULT_ACCEPTED
    m = bridge.wait_type("PARAM_VALUE", 1.0)
    assert m is not None and m.param_index == 5 and m.param_id == PARAMS[5].param
    ack = bridge.command(MAV.MAV_CMD_REQUEST_MESSAGE, 148)  # AUTOPILOT_VERSION
    assert ack is not None and ack.result == MAV.MAV_RESULT_ACCEPTED
    v = bridge.wait_type("AUTOPILOT_VERSION", 1.0)
    assert v is not None
    assert v.capabilities & (1 << 17)  # MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_C_CAST
    assert v.capabilities & (1 << 13) and v.capabilities & (1 << 3)  # MAVLINK2, COMMAND_INT
    assert not v.capabilities & (1 << 4)  # not PARAM_ENCODE_BYTEWISE
    out = subprocess.run([str(bridge.proc.args[0]), "--version"], capture_output=True, text=True)
    major, minor, patch = (int(x) for x in out.stdout.split()[-1].split("."))
    assert v.flight_sw_version == major << 24 | minor << 16 | patch << 8
    ack = bridge.command(MAV.MAV_CMD_REQUEST_MESSAGE, GPS_RAW_INT_ID)
    assert ack is not None and ack.result == MAV.MAV_RESULT_DENIED  # a message we never send
    ack = bridge.command(MAV.MAV_CMD_REQUEST_MESSAGE, float("nan"))
    assert ack is not None and ack.result == MAV.MAV_RESULT_DENIED
    # a command we do not do
    ack = bridge.command(MAV.MAV_CMD_COMPONENT_ARM_DISARM, 1)
    assert ack is not None and ack.result == MAV.MAV_RESULT_UNSUPPORTED
    # re-initialise: ACCEPTED, ODOMETRY's reset_counter goes up once the filter restarts
    before = bridge.wait_type("ODOMETRY", 1.0).reset_counter
    ack = bridge.command(MAV.MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN, 0, 0, 1, 197)
    assert ack is not None and ack.result == MAV.MAV_RESULT_ACCEPTED
    after = bridge.wait(lambda m: m.get_type() == "ODOMETRY" and m.reset_counter != before, 10.0)
    assert after is not None and after.reset_counter == (before + 1) % 256
    assert bridge.stats()["mavlink_control"]["filter_resets"] == 1


def test_another_component_is_not_answered(bridge):
    bridge.conn.mav.command_long_send(1, 1, MAV.MAV_CMD_REQUEST_MESSAGE, 0, 0, 0, 0, 0, 0, 0, 0)
    bridge.conn.mav.command_int_send(1, 1, 0, MAV.MAV_CMD_COMPONENT_ARM_DISARM, 0, 0, 1, 0, 0, 0,
                                     0, 0, 0)
    bridge.conn.mav.param_set_send(1, 1, b"NSE_GATE", 1.0, MAV.MAV_PARAM_TYPE_REAL32)
    bridge.conn.mav.param_request_list_send(1, 1)
    bridge.conn.mav.command_long_send(2, 197, MAV.MAV_CMD_REQUEST_MESSAGE, 0, 0, 0, 0, 0, 0, 0, 0)
    assert bridge.wait(lambda m: m.get_type() in ("COMMAND_ACK", "PARAM_VALUE"), 1.5) is None
    assert bridge.param("NSE_GATE").param_value == pytest.approx(site_value("noise", "gate_sigma"))


def test_system_not_in_control_sysids_is_refused(bridge_bin, kleeman_log, tmp_path, udp_port):
    b = Bridge(bridge_bin, kleeman_log[0], tmp_path, udp_port, client_sysid=42,
               extra_site="control_sysids = 255, 250\n")
    try:
        assert b.start()
        gate = b.param("NSE_GATE").param_value  # reading is for anyone
        assert b.set("NSE_GATE", 1.0).param_value == gate
        ack = b.command(MAV.MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN, 1)
        assert ack is not None and ack.result == MAV.MAV_RESULT_DENIED
        ack = b.command(MAV.MAV_CMD_REQUEST_MESSAGE, 0)  # changes nothing: answered
        assert ack is not None and ack.result == MAV.MAV_RESULT_ACCEPTED
        c = b.stats()["mavlink_control"]
        assert c["unauthorised"] == 2 and c["params_set"] == 0 and c["filter_resets"] == 0
        assert not b.param_file.exists()
    finally:
        err = b.stop()
    assert b.proc.returncode == 0, err


def key_file(tmp_path, passphrase, mode=0o600):
    """The key as MAVProxy's `signing setup PASSPHRASE` makes it: SHA-256 of the passphrase."""
    key = hashlib.sha256(passphrase.encode()).digest()
    path = tmp_path / "signing.key"
    path.write_text(key.hex() + "\n")
    os.chmod(path, mode)
    return key, path


def test_signing(bridge_bin, kleeman_log, tmp_path, udp_port):
    key, path = key_file(tmp_path, "beaconloc test")
    extra = f"signing_key_file = {path}\n"
    b = Bridge(bridge_bin, kleeman_log[0], tmp_path, udp_port, extra_site=extra, key=key)
    try:
        assert b.start()  # our key's client takes our HEARTBEAT: signed with the key
        assert b.set("NSE_GATE", 2.0).param_value == pytest.approx(2.0)
        ack = b.command(MAV.MAV_CMD_REQUEST_MESSAGE, 0)
        assert ack is not None and ack.result == MAV.MAV_RESULT_ACCEPTED
        # unsigned: refused, answered, the value unchanged
        b.conn.mav.signing.sign_outgoing = False
        assert b.set("NSE_GATE", 4.0).param_value == pytest.approx(2.0)
        ack = b.command(MAV.MAV_CMD_REQUEST_MESSAGE, 0)
        assert ack is not None and ack.result == MAV.MAV_RESULT_DENIED
        # signed with another key: dropped, not answered, counted
        b.conn.mav.signing.sign_outgoing = True
        b.conn.mav.signing.secret_key = hashlib.sha256(b"wrong").digest()
        b.conn.mav.param_set_send(1, 197, b"NSE_GATE", 4.0, MAV.MAV_PARAM_TYPE_REAL32)
        b.conn.mav.signing.secret_key = key
        assert b.wait_type("PARAM_VALUE", 1.0) is None
        assert b.param("NSE_GATE").param_value == pytest.approx(2.0)
        c = b.stats()["mavlink_control"]
        assert c["signing"] is True and c["unauthorised"] == 2 and c["signature_bad"] == 1
        assert c["params_set"] == 1
    finally:
        err = b.stop()
    assert b.proc.returncode == 0, err


def test_key_file_others_can_read_is_refused(bridge_bin, kleeman_log, tmp_path):
    _, path = key_file(tmp_path, "x", mode=0o644)
    site = tmp_path / "site.ini"
    site.write_text(SITE.read_text() + f"\nsigning_key_file = {path}\n")
    r = subprocess.run([str(bridge_bin), "--site", str(site), "--replay", str(kleeman_log[0])],
                       capture_output=True, text=True, timeout=10)
    assert r.returncode == 78
    assert "signing_key_file" in r.stderr and "chmod 600" in r.stderr
    path.write_text("not a key\n")
    os.chmod(path, 0o600)
    r = subprocess.run([str(bridge_bin), "--site", str(site), "--replay", str(kleeman_log[0])],
                       capture_output=True, text=True, timeout=10)
    assert r.returncode == 78 and "64 hex digits" in r.stderr


def test_sighup_keeps_overrides_and_takes_a_new_key(bridge_bin, kleeman_log, tmp_path, udp_port):
    key, path = key_file(tmp_path, "first")
    b = Bridge(bridge_bin, kleeman_log[0], tmp_path, udp_port,
               extra_site=f"signing_key_file = {path}\n", key=key)
    try:
        assert b.start()
        assert b.set("NSE_GATE", 2.5).param_value == pytest.approx(2.5)
        new_key, _ = key_file(tmp_path, "second")  # rotated in place, mode 0600
        b.proc.send_signal(signal.SIGHUP)
        assert b.wait(lambda m: m.get_type() == "STATUSTEXT" and "reloaded" in m.text, 3.0) \
            is None  # signed with the new key now: our old-key client drops it
        b.conn.mav.signing.secret_key = new_key
        # the override file was read again over the site file: the value holds
        assert b.param("NSE_GATE").param_value == pytest.approx(2.5)
        assert b.set("NSE_GATE", 1.5).param_value == pytest.approx(1.5)
        b.conn.mav.signing.secret_key = key  # the old key: dropped now
        b.conn.mav.param_set_send(1, 197, b"NSE_GATE", 4.0, MAV.MAV_PARAM_TYPE_REAL32)
        b.conn.mav.signing.secret_key = new_key
        assert b.param("NSE_GATE").param_value == pytest.approx(1.5)
        assert b.stats()["mavlink_control"]["signature_bad"] >= 1
    finally:
        err = b.stop()
    assert b.proc.returncode == 0, err
    assert "SIGHUP" in err and "reloaded" in err
