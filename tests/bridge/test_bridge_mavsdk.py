"""MAVSDK (the PyPI SDK pinned in .ci/requirements.txt: MAVSDK's C++ core through its Python
binding) used as an integrator's companion app would use it, against the daemon replaying a
simulated kleeman-lab log: it discovers our component (197, no autopilot), its Telemetry plugin
decodes our ODOMETRY into positions on the truth's path, a heading of the truth's and a covariance
of the filter's; its Param plugin reads the site's values and sets one, from MAVSDK's default
ground-station id 245 once [bridge] control_sysids allows it, and is refused without (the daemon's
default allows 255 alone: docs/mavlink.md "Who may change what")."""
import json
import math
import signal
import subprocess
import threading
import time

import mavsdk
import numpy as np
import pytest
from mavsdk.plugins.param import Param, ParamError, ParamResult, ProtocolVersion
from mavsdk.plugins.telemetry import Telemetry

from beaconloc_sim.site_schema import load_schema
from bridge_helpers import LOG_EPOCH_S, SITE

OUR_COMPONENT = 197  # MAV_COMP_ID_VISUAL_INERTIAL_ODOMETRY (docs/mavlink.md)


class Daemon:
    """The bridge replaying a log paced at speed x real time towards MAVSDK listening on port."""

    def __init__(self, bridge_bin, log, tmp_path, port, extra_site="", speed=1):
        self.site = tmp_path / "site.ini"
        self.site.write_text(SITE.read_text() + extra_site)
        self.stats_path = tmp_path / "stats.json"
        self.proc = subprocess.Popen(
            [str(bridge_bin), "--site", str(self.site), "--replay", str(log), "--speed", str(speed),
             "--mavlink", f"udpout:127.0.0.1:{port}", "--stats", str(self.stats_path),
             "--status-interval", "0"], stderr=subprocess.PIPE, text=True)

    def stats(self):
        self.proc.send_signal(signal.SIGUSR1)
        time.sleep(0.3)
        return json.loads(self.stats_path.read_text())

    def stop(self):
        self.proc.send_signal(signal.SIGTERM)
        _, err = self.proc.communicate(timeout=15)
        assert self.proc.returncode == 0, err
        return err


def ground_station(port):
    """A MAVSDK instance as a ground station (its default system id, 245) listening on port."""
    cfg = mavsdk.Configuration.create_with_component_type(mavsdk.ComponentType.GROUND_STATION)
    m = mavsdk.Mavsdk(cfg)
    assert m.add_any_connection(f"udpin://127.0.0.1:{port}") == mavsdk.ConnectionResult.SUCCESS
    return m, cfg.system_id


def our_system(m, timeout_s=15.0):
    """The system MAVSDK discovered from our HEARTBEATs, once its component is known."""
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        for s in m.get_systems():
            if OUR_COMPONENT in s.component_ids():
                return s
        time.sleep(0.1)
    pytest.fail(f"MAVSDK discovered no system with component {OUR_COMPONENT}")


def our_params(system):
    """MAVSDK's Param plugin addressed to our component (its default is the autopilot's, 1:
    every request would time out). This binding's select_component reports UNKNOWN where it
    has done it (the reads that follow answer), so its code is not taken as the outcome."""
    p = Param(system)
    try:
        p.select_component(OUR_COMPONENT, ProtocolVersion.V1)
    except ParamError as e:
        if e.result != ParamResult.UNKNOWN:
            raise
    return p


def test_mavsdk_telemetry_odometry(bridge_bin, kleeman_log, tmp_path, udp_port):
    log, truth_path = kleeman_log
    m, _ = ground_station(udp_port)
    daemon = Daemon(bridge_bin, log, tmp_path, udp_port, speed=2)
    got, lock = [], threading.Lock()
    try:
        s = our_system(m)
        assert s.get_system_id() == 1 and not s.has_autopilot()
        tel = Telemetry(s)

        def on_odometry(o, _):
            with lock:
                got.append((o.time_usec, o.position_body.x_m, o.position_body.y_m,
                            o.q.w, o.q.x, o.q.y, o.q.z, o.pose_covariance.covariance_matrix[0]))

        tel.subscribe_odometry(on_odometry)
        time.sleep(20)  # the log's first 40 s or so, at twice real time
    finally:
        daemon.stop()
    with lock:
        odo = np.array(got)
    truth = np.genfromtxt(truth_path, delimiter=",", names=True)
    t_sim = odo[:, 0] / 1e6 - LOG_EPOCH_S
    late = t_sim > 20.0  # after convergence
    assert late.sum() > 100, late.sum()  # ODOMETRY at 30 Hz
    # LOCAL_FRD as MAVSDK reads it: x = north = the site's y, y = east = the site's x
    xt = np.interp(t_sim[late], truth["t_sim_s"], truth["x_m"])
    yt = np.interp(t_sim[late], truth["t_sim_s"], truth["y_m"])
    err = np.hypot(odo[late, 2] - xt, odo[late, 1] - yt)
    assert np.median(err) < 0.1, np.median(err)  # the estimator's accuracy: make bench-accuracy
    # the quaternion's yaw, clockwise from north, is 90 deg less the site's heading
    w, qx, qy, qz = odo[late, 3], odo[late, 4], odo[late, 5], odo[late, 6]
    yaw = np.arctan2(2 * (w * qz + qx * qy), 1 - 2 * (qy * qy + qz * qz))
    theta = np.interp(t_sim[late], truth["t_sim_s"], np.unwrap(truth["theta_rad"]))
    dyaw = np.angle(np.exp(1j * (yaw - (math.pi / 2 - theta))))
    assert np.median(np.abs(dyaw)) < 0.05, np.median(np.abs(dyaw))
    # the pose covariance's first entry, the variance of x (m^2): the filter's, centimetres
    var_x = odo[late, 7]
    print(f"MAVSDK odometry: {late.sum()} after 20 s, median error {np.median(err) * 1e3:.1f} mm, yaw {np.degrees(np.median(np.abs(dyaw))):.2f} deg, sigma_x {math.sqrt(np.median(var_x)) * 1e3:.1f} mm")
    assert np.all(np.isfinite(var_x)) and np.all(var_x > 0), var_x
    assert 0.005 < math.sqrt(np.median(var_x)) < 0.1, math.sqrt(np.median(var_x))


def test_mavsdk_params(bridge_bin, kleeman_log, tmp_path, udp_port):
    m, gcs_id = ground_station(udp_port)
    assert gcs_id == 245  # MAVSDK's default ground-station id: not in the daemon's default list
    param_file = tmp_path / "params.ini"
    daemon = Daemon(bridge_bin, kleeman_log[0], tmp_path, udp_port,
                    f"\nparam_file = {param_file}\ncontrol_sysids = 255, {gcs_id}\n")
    try:
        p = our_params(our_system(m))
        assert p.get_param_float("NSE_GATE") == pytest.approx(3.0)  # the site's gate
        every = p.get_all_params()
        names = {q.name for q in every.float_params} | {q.name for q in every.int_params}
        assert names == {k.param for k in load_schema().params()}
        p.set_param_float("NSE_GATE", 3.5)
        assert p.get_param_float("NSE_GATE") == pytest.approx(3.5)
        c = daemon.stats()["mavlink_control"]
        assert c["params_set"] == 1 and c["unauthorised"] == 0
        assert "gate_sigma = 3.5\n" in param_file.read_text()
    finally:
        daemon.stop()


def test_mavsdk_param_set_refused_from_an_id_not_allowed(bridge_bin, kleeman_log, tmp_path, udp_port):
    m, _ = ground_station(udp_port)
    daemon = Daemon(bridge_bin, kleeman_log[0], tmp_path, udp_port)  # control_sysids: 255
    try:
        p = our_params(our_system(m))
        assert p.get_param_float("NSE_GATE") == pytest.approx(3.0)  # reading is open to all
        with pytest.raises(ParamError):  # the value comes back unchanged: MAVSDK gives up
            p.set_param_float("NSE_GATE", 3.5)
        assert p.get_param_float("NSE_GATE") == pytest.approx(3.0)
        c = daemon.stats()["mavlink_control"]
        assert c["params_set"] == 0 and c["unauthorised"] >= 1
    finally:
        err = daemon.stop()
    assert "PARAM_SET from system 245 component 190 refused" in err
