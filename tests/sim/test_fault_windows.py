"""Long runs: several faults of a kind ([faults] kidnap, kidnap2, ...), echo-storm
windows, a repeated path program, and a run simulated window by window
(simulate.run_windows, run --window) that carries bus, counters, wheels and the
bound across the windows."""
from __future__ import annotations

import math

import numpy as np
import pytest

from beaconloc_sim import simulate
from beaconloc_sim.bus import FRAME_BITS
from beaconloc_sim.cli import main as cli_main
from beaconloc_sim.encoders import unwrap_ticks
from beaconloc_sim.inifile import ConfigError
from beaconloc_sim.scenario import load_scenario
from beaconloc_sim.resources import builtin_site_path

LAP = "\n".join(f"segment{i + 2} = {s}" for i, s in enumerate(
    ["straight 6.0", "arc 90 0.5", "straight 5.0", "arc 90 0.5"] * 2))
PATH = f"[path]\nstart = 2.5, 2.5, 0\nspeed_mps = 0.45\nsegment1 = wait 5\n{LAP}\n"


def body(duration_s: float, faults: str = "", path: str = PATH, extra: str = "") -> str:
    return f"duration_s = {duration_s}\n{path}{extra}[faults]\n{faults}"


def test_numbered_fault_keys_give_every_window_in_time_order(make_scenario):
    faults = ("kidnap2 = 50, 0, -1\nkidnap = 20, 0, 1\nencoder_silence = 10, 1\n"
              "encoder_silence7 = 30, 2\nbeacon_outage = 5, 3, 2\nbeacon_outage2 = 40, 4, 1, 3\n"
              "echo_storm = 60, 10, 0.5, 0.25\n")
    scn = load_scenario(str(make_scenario(body(80, faults))))
    assert [k[0] for k in scn.kidnaps] == [20, 50]
    assert scn.kidnap == (20, 0, 1, 0.0)                 # the first one, as before
    assert scn.encoder_silences == ((10, 1), (30, 2))
    assert scn.beacon_outages == ((5, 3, (2,)), (40, 4, (1, 3)))
    assert scn.echo_storms == ((60, 10, 0.5, 0.25),)
    silent = scn.encoder_silent(np.array([9.9, 10.5, 11.0, 31.9, 32.0]))
    assert silent.tolist() == [False, True, False, True, False]
    echo, late = scn.echo_probabilities(np.array([59.0, 60.0, 69.9, 70.0]))
    assert echo.tolist() == [0.0, 0.5, 0.5, 0.0] and late.tolist() == [0.0, 0.25, 0.25, 0.0]


@pytest.mark.parametrize("faults, key, why", [
    ("kidnapx = 10, 0, 1\n", "kidnapx", "unknown key"),
    ("echo_storm = 10, 5, 1.5, 0\n", "echo_storm", "probabilities 0..1"),
    ("echo_storm3 = 10, 5, 0.3\n", "echo_storm3", "expected 4 comma-separated numbers"),
    ("kidnap = 10, 0, 1\nkidnap2 = 10, 1, 0\n", "kidnap2", "two kidnaps at the same time"),
    ("encoder_silence4 = 10, 0\n", "encoder_silence4", "duration_s must be > 0"),
    ("controller_restart = 10, -1\n", "controller_restart", "both >= 0"),
    ("controller_restart = 10, 5\ncontroller_restart2 = 12, 1\n", "controller_restart2",
     "during the pause of the one at 10 s"),
])
def test_bad_fault_windows_name_their_key(make_scenario, faults, key, why):
    with pytest.raises(ConfigError) as err:
        load_scenario(str(make_scenario(body(60, faults))))
    assert f"[faults] {key}" in str(err.value) and why in str(err.value)


def test_two_kidnaps_apply_in_turn_each_to_the_path_the_first_left():
    """Straight east at 0.5 m/s from (3, 3); at 10 s carried 4 m north; at 20 s turned
    90 degrees left about where it then is and carried 1 m east."""
    from beaconloc_sim.path import Trajectory, parse_segment
    seg = [parse_segment("straight 20", 0.5, 1.0)]
    tr = Trajectory(3.0, 3.0, 0.0, seg, 0.5, [(20.0, 1.0, 0.0, math.pi / 2), (10.0, 0.0, 4.0, 0.0)])
    st = tr.state(np.array([9.999, 10.0, 19.999, 20.0, 24.0]))
    assert (st["x_m"][1], st["y_m"][1]) == pytest.approx((8.0, 7.0), abs=1e-3)
    # picked up at (13, 7) heading east, put down at (14, 7) heading north; 4 s on: 2 m north
    assert (st["x_m"][2], st["y_m"][2]) == pytest.approx((13.0, 7.0), abs=1e-3)
    assert (st["x_m"][3], st["y_m"][3], st["theta_rad"][3]) == pytest.approx((14.0, 7.0, math.pi / 2))
    assert (st["x_m"][4], st["y_m"][4]) == pytest.approx((14.0, 9.0), abs=1e-9)
    assert tr.kidnap == (10.0, 0.0, 4.0, 0.0)


def test_repeated_program_drives_on_from_where_it_ended(make_scenario):
    once = load_scenario(str(make_scenario(body(300, ""))))
    again = load_scenario(str(make_scenario(body(300, "", extra="", path=PATH + "repeat = yes\n"))))
    program_s = once.trajectory.end_s
    assert again.trajectory.end_s >= 300
    t = np.array([12.0, 40.0])
    a, b = again.trajectory.state(t + program_s), once.trajectory.state(t)
    # the lap closes, so the second pass is the first one again (after its 5 s wait)
    assert a["x_m"] == pytest.approx(b["x_m"], abs=1e-6)
    assert a["y_m"] == pytest.approx(b["y_m"], abs=1e-6)
    assert once.trajectory.state(np.array([program_s + 50]))["v_mps"][0] == 0.0
    assert again.trajectory.state(np.array([program_s + 50]))["v_mps"][0] == pytest.approx(0.45)


def test_echo_storm_window_makes_echoes_only_inside_it(make_scenario):
    scn = load_scenario(str(make_scenario(body(90, "echo_storm = 30, 30, 0.5, 0.5\n"))))
    res = simulate.run(scn)
    f = res.firings
    inside = (f.t_s >= 30) & (f.t_s < 60)
    assert not f.strong_echo[~inside].any() and not f.late[~inside].any()
    assert 0.35 < f.strong_echo[inside].mean() < 0.65 and 0.35 < f.late[inside].mean() < 0.65


def test_every_outage_and_silence_window_is_applied(make_scenario):
    faults = ("beacon_outage = 10, 5, 2\nbeacon_outage2 = 30, 5, 4\n"
              "encoder_silence = 20, 2\nencoder_silence2 = 40, 3\n")
    res = simulate.run(load_scenario(str(make_scenario(body(60, faults)))))
    f = res.firings
    dead = ~f.alive
    assert set((f.beacon[dead & (f.t_s < 20)] + 1).tolist()) == {2}
    assert set((f.beacon[dead & (f.t_s >= 20)] + 1).tolist()) == {4}
    assert dead.sum() == pytest.approx(2 * 5 / (6 * 0.15), abs=1)
    enc_t = res.odometry["t_us"]          # encoder frames sent, on the receiver clock
    t = (enc_t - res.rx_clock.offset_us) / 1e6 / (1 + res.rx_clock.drift_ppm * 1e-6)
    gaps = np.diff(t)
    big = t[:-1][gaps > 0.5]
    assert big.tolist() == pytest.approx([20.0, 40.0], abs=0.02)
    assert gaps[gaps > 0.5].tolist() == pytest.approx([2.0, 3.0], abs=0.02)


def test_controller_restart_starts_the_cycle_again_from_beacon_1(make_scenario):
    """[faults] controller_restart: no beacon fires in the pause; then beacon 1, and the cycle
    goes on in order, one period apart, from its firing. Before the restart the firings are
    those of the run without it (the same times and beacons)."""
    faults = "controller_restart = 20.0, 0.7\ncontroller_restart2 = 40.0, 1.234\n"
    scn = load_scenario(str(make_scenario(body(60, faults))))
    plain = load_scenario(str(make_scenario(body(60, ""))))
    assert scn.controller_restarts == ((20.0, 0.7), (40.0, 1.234))
    rng = np.random.default_rng(0)
    from beaconloc_sim.physics import pulses
    f, g = pulses.make_firings(scn, rng), pulses.make_firings(plain, np.random.default_rng(0))
    before = f.t_s < 20.0
    assert np.array_equal(f.t_s[before], g.t_s[g.t_s < 20.0])
    assert np.array_equal(f.beacon[before], g.beacon[g.t_s < 20.0])
    assert not np.any((f.t_s >= 20.0) & (f.t_s < 20.7)) and not np.any((f.t_s >= 40.0) & (f.t_s < 41.234))
    T = scn.true_period_s
    for start, end in ((20.7, 40.0), (41.234, 60.0)):
        run = (f.t_s >= start) & (f.t_s < end)
        assert f.t_s[run][0] == start and f.beacon[run][0] == 0
        assert np.allclose(np.diff(f.t_s[run]), T, rtol=0, atol=1e-9)
        assert np.array_equal(f.beacon[run], np.arange(run.sum()) % scn.site.beacon_count)
    # the windows the live run takes (firings_until) hold the same firings
    parts = [pulses.make_firings(scn, rng, (a, min(a + 7.0, 60.0))) for a in np.arange(0.0, 60.0, 7.0)]
    assert np.array_equal(np.concatenate([p.t_s for p in parts]), f.t_s)
    assert np.array_equal(np.concatenate([p.beacon for p in parts]), f.beacon)


def test_controller_restart_makes_t0_unknown_to_the_bound(make_scenario):
    """The bound takes the firing time t0 as unknown again at the first firing after a restart
    (the prior's variance as process noise): the bound's t0 sigma there is the prior's
    (0.1 s) until that firing's pulses pin it again, while the position's stays where it was
    (the pose is not what the restart loses). Without the restart t0 is never let go."""
    from beaconloc_sim import crb
    scn = load_scenario(str(make_scenario(body(40, "controller_restart = 20.0, 0.7\n"))))
    res = simulate.run(scn)
    k = int(np.searchsorted(res.pcrb_t_s, 20.7))
    assert res.pcrb_t_s[k] == 20.7
    sd_t0 = np.sqrt(res.pcrb_cov[:, crb.IT0, crb.IT0])
    sd_pos = np.sqrt(res.pcrb_cov[:, crb.IX, crb.IX] + res.pcrb_cov[:, crb.IY, crb.IY])
    assert sd_t0[k - 1] < 1e-4                   # pinned before the restart
    assert sd_t0[k] < 1e-3                       # pinned again by the first firing's pulses
    # the first firing's pulses pin t0 only through the pose: the pose barely grows
    assert sd_pos[k] < 2 * sd_pos[k - 1]
    plain = simulate.run(load_scenario(str(make_scenario(body(40, "")))))
    j = int(np.searchsorted(plain.pcrb_t_s, 20.7))
    # without a restart the same instant keeps the bound's t0 far tighter than one firing gives
    assert np.sqrt(plain.pcrb_cov[j, crb.IT0, crb.IT0]) < sd_t0[k]


def windows(scn, window_s):
    return list(simulate.run_windows(scn, window_s))


def test_run_in_windows_is_one_continuous_bus():
    scn = load_scenario("kidnap", duration_s=120)
    parts = windows(scn, 25.0)
    assert len(parts) == 5
    t = np.concatenate([p.frames.t_s for p in parts])
    ids = np.concatenate([p.frames.arb_id for p in parts])
    sigs = [s for p in parts for s in p.frames.signals]
    assert np.all(np.diff(t) >= 0.9 * simulate.FRAME_BITS / scn.bus_bitrate_bps)
    assert t[-1] <= 120.0
    # rolling counters run on across the boundaries (per id and node)
    for fid, node, modulo in ((simulate.ID_PULSE, None, 8), (simulate.ID_ENCODERS, None, 16),
                              (simulate.ID_STATUS, 1, 16), (simulate.ID_STATUS, 2, 16)):
        c = np.array([s["Counter"] for s, i in zip(sigs, ids)
                      if i == fid and (node is None or s["NodeId"] == node)])
        assert np.all((np.diff(c) - 1) % modulo == 0), fid
    # node time of the encoder frames: 10 ms apart, or the kidnap's 1 s silence
    enc_us = np.array([s["NodeTime"] for s, i in zip(sigs, ids) if i == simulate.ID_ENCODERS])
    step = np.diff(enc_us) % 2**32
    assert set(step.tolist()) <= {10_000, 1_010_000}
    # wheel ticks run on: at most a 10 ms drive per 10 ms of node time (outer wheel on a
    # corner: 0.675 m/s, 44 ticks)
    left = np.array([s["LeftTicks"] for s, i in zip(sigs, ids) if i == simulate.ID_ENCODERS])
    assert (np.abs(np.diff(unwrap_ticks(left))) / (step / 10_000)).max() < 60
    # truth rows every 20 ms across the windows, and the bound goes on (no fall back to the prior)
    tr = np.concatenate([p.truth["t_sim_s"] for p in parts])
    assert np.allclose(np.diff(tr), 1 / scn.truth_rate_hz) and tr[0] == 0 and tr[-1] == 120
    pcrb = np.concatenate([p.truth["pcrb_pos_m"] for p in parts])
    assert pcrb[tr > 10].max() < 0.1
    # the odometry goes on from the previous window's pose (no jump at a boundary)
    ox = np.concatenate([p.odometry["x_m"] for p in parts])
    oy = np.concatenate([p.odometry["y_m"] for p in parts])
    assert np.hypot(np.diff(ox), np.diff(oy))[step == 10_000].max() < 0.01
    # about as many frames as the single run (different noise draws)
    assert len(t) == pytest.approx(len(simulate.run(scn).frames), rel=0.01)


def test_windowed_run_is_the_prefix_of_a_longer_one():
    short = windows(load_scenario("echo-storm", duration_s=40), 20.0)
    long = windows(load_scenario("echo-storm", duration_s=60), 20.0)
    for a, b in zip(short, long):
        assert a.frames.data == b.frames.data
        assert np.array_equal(a.frames.t_s, b.frames.t_s)
        assert np.array_equal(a.truth["pcrb_pos_m"], b.truth["pcrb_pos_m"])


def test_windowed_bound_is_the_bound_of_all_windows_events():
    """The bound at each row of a windowed run is the one of all the windows' events taken at
    once (simulate._attach_bound): an event whose pulses arrive after its window's end (carried
    as waiting) still counts, from its arrival on, in the next window's rows."""
    scn = load_scenario("fast-turns", duration_s=30)
    parts = windows(scn, 7.0)
    ends = [min(7.0 * (w + 1), 30.0) for w in range(len(parts))]
    assert any(p.pcrb_complete_s[-1] > end for p, end in zip(parts, ends))
    events = simulate.BoundEvents(*(np.concatenate([getattr(p, f) for p in parts])
                                    for f in ("pcrb_t_s", "pcrb_complete_s", "pcrb_cov")))
    truth = {k: np.concatenate([p.truth[k] for p in parts]) for k in parts[0].truth}
    once = dict(truth)
    simulate._attach_bound(once, scn, events)
    for k in ("pcrb_x_m", "pcrb_y_m", "pcrb_pos_m", "pcrb_lateral_m", "pcrb_sos_mps"):
        np.testing.assert_allclose(truth[k], once[k], rtol=1e-12, err_msg=k)


def test_cli_window_writes_log_truth_and_stats(tmp_path):
    import json
    log, truth, stats = tmp_path / "w.log", tmp_path / "w.csv", tmp_path / "w.json"
    rc = cli_main(["run", "kleeman-lab", "--duration", "50", "--window", "20", "--log", str(log),
                   "--truth", str(truth), "--stats", str(stats)])
    assert rc == 0
    st = json.loads(stats.read_text())
    lines = log.read_text().splitlines()
    assert len(lines) == st["frames"]["total"] > 5000
    assert st["frames"]["total"] == sum(v for k, v in st["frames"].items() if k != "total")
    assert st["duration_s"] == 50 and st["window_s"] == 20
    stamps = np.array([float(ln.split()[0].strip("()")) for ln in lines])
    assert np.all(np.diff(stamps) > 0) and stamps[-1] - 1_700_000_000 <= 50
    rows = truth.read_text().splitlines()
    assert rows[0].startswith("t_us,t_sim_s") and len(rows) == 1 + 50 * 50 + 1
    assert cli_main(["run", "kleeman-lab", "--window", "20", "--channel", "vcan0"]) == 64


def test_soak_scenario_has_one_fault_an_hour_in_turn():
    from pathlib import Path
    path = Path(__file__).resolve().parents[1] / "soak" / "kleeman-lab-24h.scenario.ini"
    scn = load_scenario(str(path))
    assert scn.duration_s == 86400 and scn.trajectory.end_s >= 86400
    assert scn.site.name == load_scenario("kleeman-lab").site.name
    starts = {"kidnap": [k[0] for k in scn.kidnaps],
              "beacon_outage": [o[0] for o in scn.beacon_outages],
              "echo_storm": [s[0] for s in scn.echo_storms],
              # the swing: where the profile leaves 20 C
              "temperature": [t for t, c in scn.temperature_profile[1:] if c == 20][::2],
              "controller_restart": [r[0] for r in scn.controller_restarts],
              # the receiver array (node 1) first, the encoders (node 2) a minute later
              "node_restart": [r[0] for r in scn.node_restarts if r[2] == 1]}
    silences = [s[0] for s in scn.encoder_silences if s[1] > 1.0]
    kinds = ["kidnap", "silence", "beacon_outage", "echo_storm", "temperature",
             "controller_restart", "node_restart"]
    for hour in range(24):
        t = 3600 * hour + 1800
        kind = kinds[hour % len(kinds)]
        found = silences if kind == "silence" else starts[kind]
        assert t in found, (hour, kind)
    assert sum(len(v) for v in starts.values()) + len(silences) == 24
    assert sorted((r[0], r[2]) for r in scn.node_restarts if r[2] == 2) == [
        (t + 60, 2) for t in starts["node_restart"]]
    # the robot stays in the room all day (kidnaps alternate north and back)
    st = scn.trajectory.state(np.arange(0, 86400, 7.0))
    assert st["x_m"].min() > 0.5 and st["x_m"].max() < 11.5
    assert st["y_m"].min() > 0.5 and st["y_m"].max() < 11.5
    assert scn.site.path.resolve() == builtin_site_path().resolve()


def test_misplaced_beacon_moves_the_physics_not_the_site_file(make_scenario):
    """[faults] beacon_misplaced: the beacon stands elsewhere than the site file says; the
    physics and the bound take it there, the file (the bridge's) keeps the written position."""
    from beaconloc_sim.site import load_site
    scn = load_scenario(str(make_scenario(body(10, "beacon_misplaced = 3, 0.05, -0.10\n"
                                                   "beacon_misplaced2 = 5, 0, 0, -0.2\n"))))
    written = load_site(scn.site.path).beacons_m
    moved = scn.site.beacons_m - written
    assert np.allclose(moved[2], [0.05, -0.10, 0.0]) and np.allclose(moved[4], [0, 0, -0.2])
    assert np.allclose(np.delete(moved, [2, 4], axis=0), 0.0)
    # the arrivals follow the moved beacon: beacon 3's flight times from the same path differ
    nominal = load_scenario(str(make_scenario(body(10, ""))))
    a, b = simulate.run(nominal), simulate.run(scn)
    assert np.array_equal(a.truth["x_m"], b.truth["x_m"])   # the same path
    assert not np.array_equal(a.frames.t_s, b.frames.t_s)   # other arrivals


def test_misplaced_range_beacon_moves_the_physics_not_the_site_file():
    """[faults] range_beacon_misplaced (the built-in misplaced-range-beacon): the range beacon
    stands elsewhere than marvelmind.ini says, the written site keeps it."""
    from beaconloc_sim.site import load_site
    scn = load_scenario("misplaced-range-beacon")
    written = load_site(scn.site.path)
    moved = np.asarray(scn.site.range_beacons_m) - np.asarray(written.range_beacons_m)
    assert np.allclose(moved[1], [-0.08, 0.07, 0.0])
    assert np.allclose(np.delete(moved, 1, axis=0), 0.0)
    assert np.array_equal(scn.site.beacons_m, written.beacons_m)


def test_misplaced_bearing_beacon_x_and_y_only(make_scenario):
    """[faults] bearing_beacon_misplaced (the built-in misplaced-bearing-beacon): a bearing beacon
    has no height, so the key takes x and y only."""
    from beaconloc_sim.site import load_site
    scn = load_scenario("misplaced-bearing-beacon")
    written = load_site(scn.site.path)
    moved = np.asarray(scn.site.bearing_beacons_m) - np.asarray(written.bearing_beacons_m)
    assert np.allclose(moved[1], [0.0, 0.05]) and np.allclose(np.delete(moved, 1, axis=0), 0.0)
    text = (scn.site.path.parent / "misplaced-bearing-beacon.scenario.ini").read_text()
    bad = make_scenario(text.split("[scenario]", 1)[1].split("\n", 2)[2].replace(
        "bearing_beacon_misplaced = 2, 0, 0.05", "bearing_beacon_misplaced = 2, 0, 0.05, 0.1"),
        site_text=scn.site.path.read_text())
    with pytest.raises(ConfigError, match=r"\[faults\] bearing_beacon_misplaced: expected 'id, "
                                          r"dx_m, dy_m' with id 1\.\.3"):
        load_scenario(str(bad))



PULSE, ENCODERS, STATUS = 0x100, 0x110, 0x120


def node_frames(res, arb_id, node_id=None):
    """(receive time s, signals) of one frame id (NODE_STATUS: of one NodeId), bus order."""
    return [(t, s) for t, i, s in zip(res.frames.t_s.tolist(), res.frames.arb_id.tolist(),
                                      res.frames.signals)
            if i == arb_id and (node_id is None or s["NodeId"] == node_id)]


def test_node_restart_starts_the_nodes_clock_counters_and_ticks_from_zero(make_scenario):
    """[faults] node_restart = time_s, pause_s, NodeId: the node sends nothing in the pause
    (no status frame either) and hears nothing (no detection in it reaches the bound); after
    it, its NodeTime counts from 0 at the restart, its rolling counters start at 0, the wheel
    encoders' ticks from 0 at their first sample, NODE_STATUS carries Uptime from 0 and Flags
    bit 1 for 10 s. The other nodes go on as in the run without it."""
    faults = "node_restart = 20.0, 0.3, 1\nnode_restart2 = 30.0, 0.2, 2\n"
    scn = load_scenario(str(make_scenario(body(45, faults))))
    assert scn.node_restarts == ((20.0, 0.3, 1), (30.0, 0.2, 2))
    res = simulate.run(scn)
    plain = simulate.run(load_scenario(str(make_scenario(body(45, "")))))
    for arb_id, node, (t_r, pause) in ((PULSE, 1, (20.0, 0.3)), (ENCODERS, 2, (30.0, 0.2))):
        frames = node_frames(res, arb_id)
        times = np.array([t for t, _ in frames])
        assert not np.any((times >= t_r) & (times < t_r + pause))
        after = int(np.searchsorted(times, t_r + pause))
        before_sig, first_t, first = frames[after - 1][1], times[after], frames[after][1]
        assert before_sig["NodeTime"] > 1_000_000        # the old clock: the node's age
        # the new clock read 0 at t_r + pause (the frame is received within 5 ms of its NodeTime)
        assert 0 <= first["NodeTime"] <= (first_t - t_r - pause) * 1e6
        assert first_t - t_r - pause - first["NodeTime"] * 1e-6 < 0.005
        assert first["Counter"] == 0 and frames[after + 1][1]["Counter"] == 1
        status = node_frames(res, STATUS, node)
        st_t = np.array([t for t, _ in status])
        assert not np.any((st_t >= t_r) & (st_t < t_r + pause))
        flagged = [(t, s) for t, s in status if s["Flags"] & 2]
        assert flagged and all(t_r + pause < t < t_r + pause + 10.5 for t, _ in flagged)
        assert flagged[0][1]["Uptime"] == 0 and flagged[0][1]["Counter"] == 0
        assert [s["Uptime"] for _, s in flagged] == list(range(len(flagged)))
    enc = node_frames(res, ENCODERS)
    k = next(i for i, (t, _) in enumerate(enc) if t > 30.2)
    assert (enc[k][1]["LeftTicks"], enc[k][1]["RightTicks"]) == (0, 0)
    # then they count the wheels on: 1 s later the robot has rolled 0.45 m
    later = next(s for t, s in enc if t > enc[k][0] + 1.0)
    m_per_tick = 2 * math.pi * scn.site.wheel_radius_m / scn.site.ticks_per_rev
    assert later["LeftTicks"] * m_per_tick == pytest.approx(0.45, abs=0.03)
    # the receiver heard nothing while off, and only then differs from the plain run
    assert not np.any((res.detections.edge_s >= 20.0) & (res.detections.edge_s < 20.3))
    same = (plain.detections.edge_s < 20.0) | (plain.detections.edge_s >= 20.3 + 0.03)
    keep = (res.detections.edge_s < 20.0) | (res.detections.edge_s >= 20.3 + 0.03)
    assert np.array_equal(res.detections.edge_s[keep], plain.detections.edge_s[same])
    # the encoder frames around the receiver's restart are the plain run's
    assert [s for t, s in enc if 19 < t < 21] == [s for t, s in node_frames(plain, ENCODERS)
                                                  if 19 < t < 21]


def test_receiver_restart_makes_t0_unknown_to_the_bound(make_scenario):
    """The receiver array's clock is the time base of t0: after its restart the bound takes
    t0 as unknown again at the first firing it hears (as after a controller restart), not at
    an encoder node's restart."""
    from beaconloc_sim import crb
    res = simulate.run(load_scenario(str(make_scenario(body(40, "node_restart = 20, 0.3, 1\n")))))
    enc = simulate.run(load_scenario(str(make_scenario(body(40, "node_restart = 20, 0.3, 2\n")))))
    plain = simulate.run(load_scenario(str(make_scenario(body(40, "")))))
    first = res.detections.firing[res.detections.edge_s >= 20.3].min()
    t_first = res.firings.t_s[first]
    assert 20.3 - 0.05 < t_first < 20.3 + res.scenario.site.period_s
    sd_t0 = {name: np.sqrt(r.pcrb_cov[:, crb.IT0, crb.IT0])[int(np.searchsorted(r.pcrb_t_s, t_first))]
             for name, r in (("receiver", res), ("encoders", enc), ("plain", plain))}
    assert sd_t0["plain"] < 1e-4 and sd_t0["encoders"] == pytest.approx(sd_t0["plain"])
    assert sd_t0["receiver"] > 2 * sd_t0["plain"]     # one firing pins t0 only through the pose


@pytest.mark.parametrize("faults, why", [
    ("node_restart = 10, 0.5\n", "expected 3 comma-separated numbers"),
    ("node_restart = 10, 0, 1\n", "pause_s > 0"),
    ("node_restart = 10, 0.5, 1.5\n", "node a NodeId"),
    ("node_restart = 10, 0.5, 3\n", "node 3 is not on this site's bus (its nodes: 1 receiver "
                                    "array, 2 wheel encoders)"),
    ("node_restart = 10, 1, 1\nnode_restart2 = 10.5, 1, 1\n",
     "node 1 restarts at 10.5 s during the pause of its restart at 10 s"),
])
def test_bad_node_restarts_name_their_key(make_scenario, faults, why):
    with pytest.raises(ConfigError) as err:
        load_scenario(str(make_scenario(body(60, faults))))
    assert "[faults] node_restart" in str(err.value) and why in str(err.value)


def test_node_restarts_of_two_nodes_may_overlap(make_scenario):
    scn = load_scenario(str(make_scenario(body(60, "node_restart = 10, 1, 1\n"
                                                   "node_restart2 = 10.5, 1, 2\n"))))
    assert scn.node_down(1, [10.9, 11.0]).tolist() == [True, False]
    assert scn.node_down(2, [10.4, 11.4, 11.5]).tolist() == [False, True, False]
    assert scn.node_resumes_s(1) == [11.0] and scn.node_resumes_s(6) == []


def test_backlog_moves_only_the_receive_times(make_scenario):
    """[faults] backlog = start_s, hold_s: the bridge's interface holds every frame received in
    the window and delivers them at its end, one frame time apart in bus order, the frames
    after queued behind; the frames themselves (ids, payloads, stamps) are the plain run's, and a
    windowed run (a live one, a soak) holds the same frames across its window boundary."""
    plain = simulate.run(load_scenario(str(make_scenario(body(30, "")))))
    held = load_scenario(str(make_scenario(body(30, "backlog = 11, 1.5\nbacklog2 = 20, 0.4\n"))))
    assert held.backlogs == ((11.0, 1.5), (20.0, 0.4))
    res = simulate.run(held)
    t0, t1 = plain.frames.t_s, res.frames.t_s
    assert np.array_equal(res.frames.arb_id, plain.frames.arb_id)
    assert res.frames.data == plain.frames.data
    frame_s = FRAME_BITS / held.bus_bitrate_bps
    assert np.all(np.diff(t1) >= frame_s - 1e-12)
    for start, hold in held.backlogs:
        inside = np.flatnonzero((t0 >= start) & (t0 < start + hold))
        assert len(inside) > 20
        # delivered at the hold's end, back to back
        assert t1[inside[0]] == pytest.approx(start + hold)
        assert np.allclose(np.diff(t1[inside]), frame_s)
        # and the queue drains: soon after, frames are on time again
        after = np.flatnonzero(t0 >= start + hold + 0.05)[:5]
        assert np.array_equal(t1[after], t0[after])
    outside = (t1 == t0)
    assert outside.sum() > 0.9 * len(t0)
    assert np.all(t1 >= t0)
    # windows of 4 s: the first backlog is held across the boundary at 12 s (its frames of
    # both windows delivered together at 12.5 s), the second within one window
    windowed = np.concatenate([w.frames.t_s for w in simulate.run_windows(held, 4.0)])
    plain_w = np.concatenate([w.frames.t_s for w in simulate.run_windows(
        load_scenario(str(make_scenario(body(30, "")))), 4.0)])
    for start, hold in held.backlogs:
        inside = (plain_w >= start) & (plain_w < start + hold)
        assert np.allclose(windowed[inside] - (start + hold), np.arange(inside.sum()) * frame_s)


@pytest.mark.parametrize("faults, why", [
    ("backlog = 10\n", "expected 2 comma-separated numbers"),
    ("backlog = 10, 0\n", "hold_s > 0"),
    ("backlog = 10, 2\nbacklog2 = 11, 1\n", "a backlog from 11 s inside the one from 10 s"),
])
def test_bad_backlogs_name_their_key(make_scenario, faults, why):
    with pytest.raises(ConfigError) as err:
        load_scenario(str(make_scenario(body(60, faults))))
    assert "[faults] backlog" in str(err.value) and why in str(err.value)
