"""The operator's start/stop of a team's leap-frog through the real daemon's
live path (the LD_PRELOAD CAN shim of test_bridge_live.py): COMMAND_LONG
MAV_CMD_MISSION_START / MAV_CMD_DO_PAUSE_CONTINUE to the team's host become
TEAM_COMMAND frames (0x132, decoded with cantools from the DBC) written to
the bus for the team leader, each answered with COMMAND_ACK and a
STATUSTEXT; an unsupported command is refused, another system's ignored, and
a site that is not a team's answers UNSUPPORTED without writing."""
import socket
import struct
import subprocess
import time

import cantools
import pytest
from pymavlink import mavutil

from bridge_helpers import BRIDGE, REPO, SITE, mavlink_listener

MAV = mavutil.mavlink
SHIM = BRIDGE.parents[1] / "tests" / "bridge" / "fake_can_preload.so"
ROOM = REPO / "hw_sim" / "beaconloc_sim" / "data" / "scenarios" / "millibots-room.ini"
DBC = cantools.database.load_file(str(REPO / "hw_sim" / "beaconloc_sim" / "data" / "beaconloc.dbc"))


def start(bridge_bin, site, tmp_path, port):
    if not SHIM.exists():
        pytest.fail(f"{SHIM} not built (make test-bridge-py builds it)")
    sock_path = tmp_path / "can.sock"
    srv = socket.socket(socket.AF_UNIX, socket.SOCK_SEQPACKET)
    srv.bind(str(sock_path))
    srv.listen(1)
    srv.settimeout(5)
    env = {"LD_PRELOAD": str(SHIM), "FAKE_CAN_SOCKET": str(sock_path), "PATH": "/usr/bin:/bin"}
    proc = subprocess.Popen([str(bridge_bin), "--site", str(site), "--can", "fake0",
                             "--mavlink", f"udpout:127.0.0.1:{port}", "--status-interval", "0"],
                            stderr=subprocess.PIPE, text=True, env=env)
    can, _ = srv.accept()
    can.settimeout(2)
    return proc, can, srv


def wait_for(conn, pred, timeout=3.0):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        m = conn.recv_match(blocking=True, timeout=0.2)
        if m is not None and pred(m):
            return m
    return None


def command(conn, target, cmd, param1=0.0):
    conn.mav.command_long_send(target, 197, cmd, 0, param1, 0, 0, 0, 0, 0, 0)


def read_team_command(can):
    raw = can.recv(16)
    fid, dlc, data = struct.unpack("<IB3x8s", raw)
    assert fid == 0x132 and dlc == 8
    return DBC.decode_message(fid, data)


def stop(proc, can, srv):
    proc.terminate()
    _, err = proc.communicate(timeout=10)
    can.close()
    srv.close()
    return err


def test_leapfrog_start_pause_resume(bridge_bin, tmp_path, udp_port):
    conn = mavlink_listener(udp_port)
    proc, can, srv = start(bridge_bin, ROOM, tmp_path, udp_port)
    try:
        # the host's own HEARTBEAT (system 1) tells the listener where it is
        assert wait_for(conn, lambda m: m.get_type() == "HEARTBEAT" and m.get_srcSystem() == 1)
        expected = [(MAV.MAV_CMD_MISSION_START, 0.0, 1, "start"),
                    (MAV.MAV_CMD_DO_PAUSE_CONTINUE, 0.0, 2, "pause"),
                    (MAV.MAV_CMD_DO_PAUSE_CONTINUE, 1.0, 3, "resume")]
        for seq, (cmd, p1, code, word) in enumerate(expected):
            command(conn, 1, cmd, p1)
            frame = read_team_command(can)
            assert frame["Command"] == code and frame["Leader"] == 1
            assert frame["Sequence"] == seq and frame["Counter"] == seq
            ack = wait_for(conn, lambda m: m.get_type() == "COMMAND_ACK")
            assert ack is not None and ack.command == cmd
            assert ack.result == MAV.MAV_RESULT_ACCEPTED
            assert ack.target_system == 255  # the listener's source_system
            txt = wait_for(conn, lambda m: m.get_type() == "STATUSTEXT" and "leap-frog" in m.text)
            assert txt is not None and f"leap-frog {word} sent to robot 1" in txt.text
        # a command we do not do: refused, nothing on the bus
        command(conn, 1, MAV.MAV_CMD_COMPONENT_ARM_DISARM, 1.0)
        ack = wait_for(conn, lambda m: m.get_type() == "COMMAND_ACK")
        assert ack.result == MAV.MAV_RESULT_UNSUPPORTED
        # another system's: ignored
        command(conn, 42, MAV.MAV_CMD_MISSION_START)
        assert wait_for(conn, lambda m: m.get_type() == "COMMAND_ACK", timeout=1.0) is None
        with pytest.raises(socket.timeout):
            can.recv(16)
    finally:
        err = stop(proc, can, srv)
        conn.close()
    assert proc.returncode == 0, err


def test_not_a_team_site(bridge_bin, tmp_path, udp_port):
    conn = mavlink_listener(udp_port)
    proc, can, srv = start(bridge_bin, SITE, tmp_path, udp_port)
    try:
        assert wait_for(conn, lambda m: m.get_type() == "HEARTBEAT")
        command(conn, 1, MAV.MAV_CMD_MISSION_START)
        ack = wait_for(conn, lambda m: m.get_type() == "COMMAND_ACK")
        assert ack is not None and ack.result == MAV.MAV_RESULT_UNSUPPORTED
        with pytest.raises(socket.timeout):
            can.recv(16)
    finally:
        err = stop(proc, can, srv)
        conn.close()
    assert proc.returncode == 0, err
