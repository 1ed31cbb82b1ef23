"""beaconloc-view's state model and sources on MAVLink encoded here (pymavlink): the
ODOMETRY frame mapping back to the site frame, the 3-sigma ellipse, beacon states from
STATUSTEXT (lost / back / echo storm, kinds), a team (one robot per system id), other
components ignored, the trail's increments and its break at a reset, a followed file."""
from __future__ import annotations

import math
import os

import numpy as np
import pytest

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

from beaconloc_sim.mavframe import (ellipse_axes, odometry_site_heading_rad,  # noqa: E402
                                    odometry_site_pos_cov, odometry_site_xy)
from beaconloc_sim.resources import builtin_site_path  # noqa: E402
from beaconloc_sim.site import load_site  # noqa: E402
from beaconloc_sim.view.source import FollowFile  # noqa: E402
from beaconloc_sim.view.state import ViewState  # noqa: E402

ML = mavutil.mavlink
NAN = float("nan")


def wire(msg, sysid=1, compid=197) -> bytes:
    return msg.pack(ML.MAVLink(None, srcSystem=sysid, srcComponent=compid))


def received(msg, sysid=1, compid=197):
    """The message as a receiver gets it (header with the sender's ids)."""
    return ML.MAVLink(None).parse_buffer(wire(msg, sysid, compid))[0]


def odometry(x_site, y_site, theta_rad, cov_site=((1e-4, 0.0), (0.0, 1e-4)), reset=0, t_us=1):
    """ODOMETRY as docs/mavlink.md specifies it from a site-frame pose: x north = y_site,
    y east = x_site, yaw psi = pi/2 - theta about down; the position covariance swapped."""
    psi = math.pi / 2 - theta_rad
    q = [math.cos(psi / 2), 0.0, 0.0, math.sin(psi / 2)]
    cov = [NAN] * 21
    cov[0], cov[1], cov[6] = cov_site[1][1], cov_site[0][1], cov_site[0][0]
    return ML.MAVLink_odometry_message(t_us, ML.MAV_FRAME_LOCAL_FRD, ML.MAV_FRAME_BODY_FRD,
                                       y_site, x_site, 0.0, q, 0, 0, 0, 0, 0, 0, cov, [NAN] * 21,
                                       reset, ML.MAV_ESTIMATOR_TYPE_VISION, 80)


def text(t, severity=ML.MAV_SEVERITY_WARNING):
    return ML.MAVLink_statustext_message(severity, t.encode(), 0, 0)


@pytest.fixture
def state():
    return ViewState(load_site(builtin_site_path()))


def test_odometry_back_in_the_site_frame():
    for theta in (0.0, 0.5, 2.0, -1.2, math.pi):
        cov = np.array([[4e-4, 1.5e-4], [1.5e-4, 1e-4]])
        m = received(odometry(3.0, 7.5, theta, cov))
        assert odometry_site_xy(m) == pytest.approx((3.0, 7.5), abs=1e-6)
        d = (odometry_site_heading_rad(m) - theta + math.pi) % (2 * math.pi) - math.pi
        assert abs(d) < 1e-6
        assert odometry_site_pos_cov(m) == pytest.approx(cov, rel=1e-6)


def test_three_sigma_ellipse():
    # a covariance with known axes: sigma 0.02 m along 30 deg, 0.01 m across
    a, b, ang = 0.02, 0.01, math.radians(30)
    r = np.array([[math.cos(ang), -math.sin(ang)], [math.sin(ang), math.cos(ang)]])
    cov = r @ np.diag([a * a, b * b]) @ r.T
    major, minor, angle = ellipse_axes(cov, 3.0)
    assert (major, minor) == pytest.approx((3 * a, 3 * b), rel=1e-9)
    assert math.tan(angle) == pytest.approx(math.tan(ang), rel=1e-9)  # the axis, either way
    assert ellipse_axes(np.array([[1.0, 0.0], [0.0, NAN]])) is None
    assert ellipse_axes(np.array([[1.0, 2.0], [2.0, 1.0]])) is None   # not PSD


def test_beacon_states_from_statustext(state):
    beacons = lambda: {(b["kind"], b["n"]): b["state"] for b in state.snapshot({})["beacons"]}  # noqa: E731
    assert set(beacons().values()) == {"unknown"}          # no estimate yet
    state.ingest(received(odometry(2.5, 2.5, 0.0)))
    assert set(beacons().values()) == {"heard"}
    state.ingest(received(text("beaconloc: beacon 3 lost")))
    assert beacons()[("ultrasonic", 3)] == "lost"
    state.ingest(received(text("beaconloc: echo storm: 45% echoes or rejected")))
    got = beacons()
    assert got[("ultrasonic", 3)] == "lost"
    assert {got[("ultrasonic", n)] for n in (1, 2, 4, 5, 6)} == {"echoing"}
    state.ingest(received(text("beaconloc: echo storm over", ML.MAV_SEVERITY_NOTICE)))
    state.ingest(received(text("beaconloc: beacon 3 back", ML.MAV_SEVERITY_NOTICE)))
    assert set(beacons().values()) == {"heard"}
    events = state.snapshot({})["events"]
    assert [e["text"] for e in events][-1] == "beaconloc: beacon 3 back"
    assert events[-1]["severity"] == "notice"


def test_other_kinds_of_beacons():
    site = load_site(builtin_site_path("eurobot"))
    st = ViewState(site)
    st.ingest(received(odometry(1.0, 1.0, 0.0)))
    kinds = {(b["kind"], b["n"]): b["state"] for b in st.snapshot({})["beacons"]}
    assert set(kinds) == {("bearing", n) for n in range(1, site.bearing_beacon_count + 1)}
    assert set(kinds.values()) == {"unreported"}           # the bridge says nothing of them
    st.ingest(received(text("bearing beacon 2 lost")))
    st.ingest(received(text("bearing beacon 1 back")))
    kinds = {(b["kind"], b["n"]): b["state"] for b in st.snapshot({})["beacons"]}
    assert kinds[("bearing", 2)] == "lost" and kinds[("bearing", 1)] == "heard"


def test_team_one_robot_per_system_id_and_other_components_ignored(state):
    state.ingest(received(odometry(1.0, 2.0, 0.0), sysid=1))
    state.ingest(received(odometry(4.0, 5.0, 1.0), sysid=3))
    state.ingest(received(odometry(9.0, 9.0, 0.0), sysid=2, compid=1))   # an autopilot's
    hb = ML.MAVLink_heartbeat_message(ML.MAV_TYPE_ONBOARD_CONTROLLER, ML.MAV_AUTOPILOT_INVALID,
                                      0, 0, ML.MAV_STATE_ACTIVE, 3)
    state.ingest(received(hb, sysid=3))
    state.ingest(received(ML.MAVLink_named_value_float_message(5, b"sos_mps", 343.5), sysid=3))
    snap = state.snapshot({})
    assert [r["sysid"] for r in snap["robots"]] == [1, 3]
    r1, r3 = snap["robots"]
    assert (r1["pose"]["x_m"], r1["pose"]["y_m"]) == pytest.approx((1.0, 2.0))
    assert (r3["pose"]["x_m"], r3["pose"]["y_m"]) == pytest.approx((4.0, 5.0))
    assert r3["health"] == "active" and r1["health"] is None
    assert r3["values"] == {"sos_mps": pytest.approx(343.5)}


def test_trail_increments_and_break_at_reset(state):
    cursors: dict[int, int] = {}
    for i in range(5):
        state.ingest(received(odometry(1.0 + 0.1 * i, 1.0, 0.0, t_us=i + 1)))
    first = state.snapshot(cursors)["robots"][0]
    assert first["trail_restart"] and len(first["trail_new"]) == 5
    state.ingest(received(odometry(1.4 + 0.001, 1.0, 0.0, t_us=6)))   # < 1 cm: no point
    assert state.snapshot(cursors)["robots"][0]["trail_new"] == []
    state.ingest(received(odometry(3.0, 3.0, 0.0, reset=1, t_us=7)))  # re-initialised
    new = state.snapshot(cursors)["robots"][0]
    assert not new["trail_restart"]
    assert new["trail_new"] == [None, [3.0, 3.0]]
    # a new page gets the whole trail
    assert len(state.snapshot({})["robots"][0]["trail_new"]) == 7


def test_follow_a_growing_file(tmp_path):
    path = tmp_path / "mavlink.raw"
    f = FollowFile(str(path))
    assert f.poll() == []                                   # not there yet
    frames = b"".join(wire(odometry(1.0 * i, 2.0, 0.0)) for i in range(3))
    path.write_bytes(frames[:50])                           # a frame cut in the middle
    got = f.poll()
    with path.open("ab") as fh:
        fh.write(frames[50:])
    got += f.poll()
    assert [m.get_type() for m in got] == ["ODOMETRY"] * 3
    assert [odometry_site_xy(m)[0] for m in got] == [0.0, 1.0, 2.0]
    path.unlink()                                          # replaced (make demo starts again)
    path.write_bytes(wire(text("beaconloc: converged")))
    assert [m.get_type() for m in f.poll()] == ["STATUSTEXT"]
    f.close()
