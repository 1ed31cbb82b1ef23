"""The bearing-sensor node (BEARING frames), its outages and occlusions, the rotating
sensor, the eurobot scenarios and the posterior bound with bearings."""
from __future__ import annotations

import hashlib
import math
import re

import cantools
import numpy as np
import pytest

from beaconloc_sim import crb, simulate
from beaconloc_sim.nodes.bearing_sensor import BearingSensor, bearing_rows, encode_bearing_deg
from beaconloc_sim.physics.bearings import bearing_jacobian, bearing_rad, wrap_rad
from beaconloc_sim.resources import builtin_scenario_path, dbc_path
from beaconloc_sim.scenario import load_scenario

EUROBOT_SITE = (builtin_scenario_path("eurobot").parent / "eurobot.ini").read_text()
DB = cantools.database.load_file(str(dbc_path()))
BEARING = DB.get_message_by_name("BEARING")
ID_BEARING = BearingSensor.frame_spec().frame_id
B_M = np.array([[3.0, 2.1], [0.0, 1.05], [3.0, 0.0]])     # Vander 2011 Fig. 1


def eurobot_site(**keys) -> str:
    """The eurobot site text with 'key' = value replaced (each key appears once)."""
    text = EUROBOT_SITE
    for key, value in keys.items():
        text, n = re.subn(rf"^{key}\s*=[^\n]*", f"{key} = {value}", text, flags=re.MULTILINE)
        assert n == 1, key
    return text


# a robot standing at the table's centre facing beacon B2 (bearing 0: wraps at 0/360)
STANDING = "[path]\nstart = 1.5, 1.05, 180\n"


def decoded_bearings(res):
    """(t_rx_s, beacon 1.., bearing_deg, node_us, quality) of every BEARING frame, decoded by
    cantools from the encoded bytes."""
    rows = [(t, BEARING.decode(d)) for t, i, d in zip(res.frames.t_s, res.frames.arb_id,
                                                      res.frames.data) if i == BEARING.frame_id]
    return (np.array([t for t, _ in rows]), np.array([s["Beacon"] for _, s in rows]),
            np.array([s["Bearing"] for _, s in rows], dtype=float),
            np.array([s["NodeTime"] for _, s in rows], dtype=np.int64),
            np.array([s["Quality"] for _, s in rows]))


def test_frames_decode_to_the_true_bearing_within_sigma_and_wrap_at_0_360(make_scenario):
    scn = load_scenario(make_scenario("duration_s = 60\n" + STANDING, eurobot_site()))
    res = simulate.run(scn)
    _, beacon, deg, node_us, quality = decoded_bearings(res)
    assert sorted(set(beacon.tolist())) == [1, 2, 3]
    assert len(deg) == 3 * 600                    # a scan every 0.1 s, nothing lost
    true = bearing_rad(1.5, 1.05, math.pi, B_M)   # (3,)
    err = wrap_rad(np.radians(deg) - true[beacon - 1])
    sigma = math.radians(1.0)
    # sigma of 1803 draws within 7 % (the std of a sample std is sigma / sqrt(2 n) = 1.7 %)
    assert np.std(err) == pytest.approx(sigma, rel=0.07)
    assert abs(np.mean(err)) < 4 * sigma / math.sqrt(len(err))
    # B2 straight ahead: its bearings wrap, read just below 360 or just above 0, never 360
    b2 = deg[beacon == 2]
    assert np.all((deg >= 0) & (deg < 360))
    assert np.sum(b2 > 350) > 100 and np.sum(b2 < 10) > 100
    # Quality: 1/r^2 from 1 m (B2 at 1.5 m: 255/2.25 = 113)
    assert np.all(quality[beacon == 2] == 113)
    # NodeTime: the node clock at the scan instants (every 100 000 us of its own clock),
    # the three bearings of a scan at the same instant
    assert np.all(node_us % 100_000 == 0)
    assert node_us.min() == 987_700_000            # [clocks] bearing_offset_us 987654321
    assert np.all(np.unique(node_us, return_counts=True)[1] == 3)


def test_bearing_encoding_wraps_360_to_0_on_the_dbc_step():
    step = 360 / 65536
    assert encode_bearing_deg(-1e-9, step) == 0.0            # raw 65536 -> 0
    assert encode_bearing_deg(2 * math.pi - 1e-9, step) == 0.0
    assert encode_bearing_deg(math.radians(359.999), step) == 0.0     # 65535.8 steps -> 0
    assert encode_bearing_deg(math.pi, step) == 180.0
    assert encode_bearing_deg(-math.pi / 2, step) == 270.0
    assert encode_bearing_deg(math.radians(0.6 * step), step) == step
    raw = BEARING.encode({"NodeTime": 0, "Beacon": 1, "Bearing": float(encode_bearing_deg(
        math.radians(359.995), step)), "Quality": 1, "Counter": 0})
    assert BEARING.decode(raw)["Bearing"] == pytest.approx(360 - step)


def _runs(flags: np.ndarray) -> list[int]:
    """Lengths of the runs of True."""
    edges = np.diff(np.concatenate([[0], flags.astype(int), [0]]))
    return (np.flatnonzero(edges == -1) - np.flatnonzero(edges == 1)).tolist()


@pytest.mark.parametrize("burst_s, mean_scans", [(0.5, 5.0), (0.0, 1 / 0.7)])
def test_outage_share_and_burst_length(make_scenario, burst_s, mean_scans):
    scn = load_scenario(make_scenario(
        "duration_s = 300\n" + STANDING +
        f"[bearings]\noutage_probability = 0.3\noutage_burst_s = {burst_s}\n", eurobot_site()))
    res = simulate.run(scn, encode=False)
    b = res.bearings
    # share of lost scans: 0.3 (std about 0.012 over 3 beacons with 5-scan bursts)
    assert np.mean(b.outage) == pytest.approx(0.3, abs=0.04)
    runs = sum((_runs(b.outage[b.beacon == j]) for j in range(3)), [])
    assert np.mean(runs) == pytest.approx(mean_scans, rel=0.15)
    # what is lost is not sent
    assert np.sum(res.frames.arb_id == ID_BEARING) == np.sum(~b.outage)


def test_outage_probability_per_beacon(make_scenario):
    scn = load_scenario(make_scenario("duration_s = 100\n" + STANDING +
                                      "[bearings]\noutage_probability = 0, 0.5, 0.9\n",
                                      eurobot_site()))
    b = simulate.run(scn, encode=False).bearings
    share = [np.mean(b.outage[b.beacon == j]) for j in range(3)]
    assert share[0] == 0.0
    assert share[1] == pytest.approx(0.5, abs=0.06)
    assert share[2] == pytest.approx(0.9, abs=0.04)


def test_a_burst_too_short_for_the_outage_share_is_refused(make_scenario):
    from beaconloc_sim.inifile import ConfigError
    with pytest.raises(ConfigError, match="outage_burst_s"):
        load_scenario(make_scenario("duration_s = 10\n" + STANDING +
                                    "[bearings]\noutage_probability = 0.9\noutage_burst_s = 0.2\n",
                                    eurobot_site()))


def test_a_beacon_behind_a_wall_is_never_sent(make_scenario):
    # a wall between the robot and B2 (0, 1.05); B1 and B3 stay in view
    scn = load_scenario(make_scenario("duration_s = 20\n" + STANDING +
                                      "[obstacles]\nsegment1 = 0.5, 0.5, 0.5, 1.6\n",
                                      eurobot_site()))
    res = simulate.run(scn)
    _, beacon, *_ = decoded_bearings(res)
    assert np.sum(beacon == 2) == 0
    assert np.sum(beacon == 1) == np.sum(beacon == 3) == 200
    assert np.all(res.bearings.occluded == (res.bearings.beacon == 1))


def test_beacons_beyond_max_range_are_not_sent(make_scenario):
    # from (1.5, 1.05): B2 at 1.5 m, B1 and B3 at 1.83 m
    scn = load_scenario(make_scenario("duration_s = 5\n" + STANDING +
                                      "[bearings]\nmax_range_m = 1.7\n", eurobot_site()))
    res = simulate.run(scn)
    _, beacon, *_ = decoded_bearings(res)
    assert set(beacon.tolist()) == {2} and len(beacon) == 50
    assert np.array_equal(res.bearings.out_of_range, res.bearings.beacon != 1)


def test_the_opponent_hides_a_beacon_while_it_crosses_the_line_of_sight(make_scenario):
    # robot at (1.5, 1.05) looking at B2 = (0, 1.05): the line of sight is y = 1.05. The
    # opponent (radius 0.1 m) drives up x = 0.75 from y = 0.05 at 0.1 m/s: it hides B2 while
    # |y - 1.05| < 0.1 m, that is from 9 s to 11 s, and nothing else
    scn = load_scenario(make_scenario(
        "duration_s = 20\n" + STANDING +
        "[opponent]\nradius_m = 0.1\nstart = 0.75, 0.05, 90\nspeed_mps = 0.1\n"
        "segment1 = straight 1.9\n", eurobot_site()))
    b = simulate.run(scn, encode=False).bearings
    assert set(b.beacon[b.occluded].tolist()) == {1}
    scans = np.unique(b.t_s)
    expected = scans[np.abs(0.05 + 0.1 * scans - 1.05) < 0.1]
    assert np.array_equal(b.t_s[b.occluded], expected)
    assert len(expected) == 20 and expected.min() > 9.0 and expected.max() < 11.0


def test_rotating_sensor_times_each_bearing_where_the_beam_crosses_the_beacon(make_scenario):
    # a turning, moving robot: the beacons' bearings change during a scan
    scn = load_scenario(make_scenario(
        "duration_s = 12\n[path]\nstart = 0.3, 0.3, 60\nspeed_mps = 0.3\n"
        "segment1 = arc -120 1.386\n", eurobot_site(rotating=1)))
    res = simulate.run(scn)
    b = res.bearings
    clock = res.rx_clock                           # the bearing node's (no ultrasonic beacons)
    t_scan = clock.true_time_s(b.scan)
    period = clock.true_time_s(b.scan + 100_000) - t_scan
    # inside its scan, and the beam (counter-clockwise from forward at the scan start) points
    # at the beacon's true bearing at that instant, the robot having moved
    assert np.all((b.t_s >= t_scan) & (b.t_s < t_scan + period))
    beam = 2 * np.pi * (b.t_s - t_scan) / period
    st = scn.trajectory.state(b.t_s)
    phi = bearing_rad(st["x_m"], st["y_m"], st["theta_rad"], B_M)[np.arange(len(b.t_s)), b.beacon]
    assert np.max(np.abs(wrap_rad(beam - phi))) < 1e-9
    assert np.max(np.abs(wrap_rad(phi - b.true_rad))) < 1e-12
    # crossings per beacon: one per scan, less one per turn the beacon's bearing makes
    # the beam's way (the robot turns clockwise by 120 deg: the bearings increase)
    n_scans = len(np.unique(b.scan))
    t = np.linspace(t_scan.min(), t_scan.max() + period.max(), 2000)
    st_d = scn.trajectory.state(t)
    phi_d = np.unwrap(bearing_rad(st_d["x_m"], st_d["y_m"], st_d["theta_rad"], B_M), axis=0)
    for j in range(3):
        turns = (phi_d[-1, j] - phi_d[0, j]) / (2 * np.pi)
        assert n_scans - turns - 1 <= np.sum(b.beacon == j) <= n_scans - turns + 1
    assert len(b.t_s) < 3 * n_scans
    # the frames: NodeTime = the node clock at the crossing; the bearing within noise of the
    # pose at that time; the bearings of a scan at different times
    _, beacon, deg, node_us, _ = decoded_bearings(res)
    order = np.argsort(b.t_s)
    assert sorted(node_us.tolist()) == sorted((clock.unwrapped_us(b.t_s) % 2**32).tolist())
    frames = {(int(n), int(j)): d for n, j, d in zip(node_us, beacon, deg)}
    err = [wrap_rad(math.radians(frames[(int(clock.unwrapped_us(t) % 2**32), int(j) + 1)]) - p)
           for t, j, p in zip(b.t_s[order], b.beacon[order], b.true_rad[order])]
    assert np.std(err) == pytest.approx(math.radians(1.0), rel=0.15)
    assert len(np.unique(node_us)) == len(node_us)


def test_eurobot_goes_lower_left_to_lower_right_in_about_10_s():
    scn = load_scenario("eurobot")
    st = scn.trajectory.state(np.linspace(0, scn.duration_s, 1201))
    assert (st["x_m"][0], st["y_m"][0]) == pytest.approx((0.3, 0.3))
    moving = np.flatnonzero(st["v_mps"] > 0)
    t_end = np.linspace(0, scn.duration_s, 1201)[moving[-1]]
    assert 9.0 < t_end < 11.0
    end = scn.trajectory.state(np.array([t_end + 0.5]))
    assert end["x_m"][0] > 2.5 and end["y_m"][0] < 0.5          # lower-right corner
    inside = (st["x_m"] > 0.2) & (st["x_m"] < 2.8) & (st["y_m"] > 0.2) & (st["y_m"] < 1.9)
    assert inside.all()                                         # a 0.2 m robot stays on the table
    assert scn.site.beacon_count == 0 and scn.site.bearing_beacon_count == 3


@pytest.mark.parametrize("name", ["eurobot", "eurobot-outage20", "eurobot-outage50",
                                  "eurobot-opponent"])
def test_eurobot_scenarios_run_and_decode(name):
    res = simulate.run(load_scenario(name))
    ids = set(res.frames.arb_id.tolist())
    assert simulate.ID_PULSE not in ids and ID_BEARING in ids
    for fid, data in zip(res.frames.arb_id, res.frames.data):
        DB.get_message_by_frame_id(int(fid)).decode(data)
    status = DB.get_message_by_name("NODE_STATUS")
    node_ids = {status.decode(d)["NodeId"] for i, d in zip(res.frames.arb_id, res.frames.data)
                if i == status.frame_id}
    assert node_ids == {2, 3}                                   # encoders and bearing sensor
    assert np.all(np.isfinite(res.truth["pcrb_pos_m"]))
    assert res.truth["pcrb_pos_m"][-1] < 0.02
    lost = {"eurobot": 0.0, "eurobot-outage20": 0.2, "eurobot-outage50": 0.5}
    if name in lost:
        assert np.mean(res.bearings.outage) == pytest.approx(lost[name], abs=0.1)
    else:
        assert np.mean(res.bearings.occluded) > 0.05


def _static_bound(pose, counts, sigma, prior=(1.0, 1.0, 0.5), offset=(0.0, 0.0)):
    """Static Cramer-Rao bound of (x, y, theta) from counts[j] bearings of each beacon:
    J = prior + sum_j n_j H_j^T H_j / sigma^2, H_j = d(phi_j)/d(x, y, theta) (Vander eq. 1)."""
    H = bearing_jacobian(*pose, B_M, offset)
    J = np.diag(1.0 / np.square(prior)) + sum(n * np.outer(h, h) for n, h in zip(counts, H)) \
        / sigma ** 2
    return np.linalg.inv(J)


def test_pcrb_of_a_standing_robot_is_the_static_bound_closed_form():
    # a robot that never moves, with noiseless wheels (the pose has no process noise):
    # the recursion's (x, y, theta) block is exactly the static bound of the bearings
    pose = (0.8, 0.6, 0.4)
    offset = (0.05, -0.02)
    sigma = math.radians(1.0)
    model = crb.BoundModel(sigma_arrival_s=2e-4, sigma_wheel_per_m=0.0, wheel_base_m=0.25,
                           ring_radius_m=0.1, rx_height_m=0.3, m_per_tick=1e-12,
                           prior_sigma=(1.0, 1.0, 0.5, 0.5, 0.5, 5.0, 1e-4, 0.1))
    k = 50
    states = np.tile([*pose, 0.0, 0.0, 343.0, 0.15, 0.0], (k, 1))
    t = 0.1 * np.arange(k)
    seen = [B_M if i % 2 == 0 else B_M[:2] for i in range(k)]   # B3 every other scan
    cov = crb.pcrb_along_path(states, np.zeros((0, 3)), np.zeros(k, int), [[]] * k,
                              np.zeros(k), np.zeros(k), model, event_time_s=t,
                              fires=np.zeros(k, bool),
                              measurements=[bearing_rows(seen, sigma, offset)])
    for n in (1, 10, 50):
        counts = (n, n, (n + 1) // 2)
        assert cov[n - 1][:3, :3] == pytest.approx(_static_bound(pose, counts, sigma,
                                                                 offset=offset), rel=1e-6)


def test_pcrb_of_a_standing_robot_on_eurobot_approaches_the_static_bound(make_scenario):
    """The simulator's bound on the eurobot site (the encoders' tick quantisation is the only
    process noise of a standing robot) against the static bound of the bearings delivered."""
    scn = load_scenario(make_scenario("duration_s = 30\n[path]\nstart = 1.5, 1.05, 180\n"
                                      "[bearings]\noutage_probability = 0.3\n", eurobot_site()))
    res = simulate.run(scn, encode=False)
    b = res.bearings
    sigma = math.radians(1.0)
    for t_end in (1.0, 5.0, 30.0):
        counts = [np.sum(b.sent & (b.beacon == j) & (b.t_s <= t_end + 1e-9)) for j in range(3)]
        static = _static_bound((1.5, 1.05, math.pi), counts, sigma)
        row = np.searchsorted(res.truth["t_sim_s"], t_end - 1e-9)
        pcrb = res.truth["pcrb_pos_m"][row]
        static_pos = math.sqrt(static[0, 0] + static[1, 1])
        # never below the static bound; within 5 % of it (quantisation noise of the heading)
        assert static_pos <= pcrb * (1 + 1e-9)
        assert pcrb == pytest.approx(static_pos, rel=0.05)


def test_a_mixed_site_fuses_firings_and_bearings():
    """kleeman-lab with three bearing beacons too: the bound has an event per firing and per
    scan, and is below the bound of the pulses alone."""
    import tempfile
    from pathlib import Path
    site_text = builtin_scenario_path("kleeman-lab").parent.joinpath("kleeman-lab.ini").read_text()
    site_text += ("\n[bearing_beacons]\ncount = 3\n[bearing_beacon1]\nx_m = 0.0\ny_m = 0.0\n"
                  "[bearing_beacon2]\nx_m = 12.0\ny_m = 0.0\n[bearing_beacon3]\nx_m = 6.0\n"
                  "y_m = 12.0\n[bearing_sensor]\nsigma_deg = 1.0\nscan_rate_hz = 10\n")
    scn_text = builtin_scenario_path("kleeman-lab").read_text().replace("kleeman-lab.ini",
                                                                         "mixed.ini")
    with tempfile.TemporaryDirectory() as d:
        Path(d, "mixed.ini").write_text(site_text)
        Path(d, "mixed.scenario.ini").write_text(scn_text)
        mixed = simulate.run(load_scenario(str(Path(d, "mixed.scenario.ini")), duration_s=30))
    pulses = simulate.run(load_scenario("kleeman-lab", duration_s=30))
    assert len(mixed.pcrb_t_s) == len(pulses.firings.t_s) + len(np.unique(mixed.bearings.t_s))
    ids = set(mixed.frames.arb_id.tolist())
    assert {simulate.ID_PULSE, ID_BEARING} <= ids
    late = mixed.truth["t_sim_s"] > 5
    assert np.all(mixed.truth["pcrb_pos_m"][late] < pulses.truth["pcrb_pos_m"][late])


def test_existing_sites_unchanged(tmp_path):
    """kleeman-lab's log and truth (with its bound) are those of the simulator before the
    bearing node existed: sha256 recorded on the schema branch (08b7878); the truth's re-recorded
    when its bound (the pcrb_* columns, all the others unchanged) was carried to each row's
    instant (issue 14)."""
    from beaconloc_sim import can_out, outputs
    res = simulate.run(load_scenario("kleeman-lab", duration_s=20))
    can_out.write_log(res.frames, tmp_path / "l.log", res.scenario.log_epoch_s, "vcan0")
    outputs.write_truth(tmp_path / "t.csv", res)
    log = hashlib.sha256((tmp_path / "l.log").read_bytes()).hexdigest()
    truth = hashlib.sha256((tmp_path / "t.csv").read_bytes()).hexdigest()
    assert log == "8332fbc4b3052e363531605b9f6615354a97cde7f307fe46a1d44a51d4cafdf9"
    assert truth == "074ee505d7afa836ade0aa0b1a88310fc4e311b3e4cac1922919c224d87866c0"
