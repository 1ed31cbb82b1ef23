"""Fault scenarios of the simulator replayed through the real daemon: the
estimator glue's re-initialisation, encoder-silence handling and health
events (the same events go to the log and to STATUSTEXT)."""
import json
import re
import subprocess

import numpy as np
import pytest

from bridge_helpers import SITE, kidnap_scenario, run_sim

BEACON_CYCLE_S = 6 * 0.150


def replay(bridge_bin, log, tmp_path, *extra, site=SITE):
    est, stats = tmp_path / "est.csv", tmp_path / "stats.json"
    p = subprocess.run([str(bridge_bin), "--site", str(site), "--replay", str(log),
                        "--mavlink", "udpout:127.0.0.1:9", "--estimates", str(est),
                        "--stats", str(stats), "--status-interval", "0", *extra],
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    return p, np.genfromtxt(est, delimiter=",", names=True), json.loads(stats.read_text())


def scenario_with(tmp_path, name, keys):
    """The built-in scenario `name` with its lines of the given keys replaced ("key = value"; a
    value None drops the line) and its site the repository's site file; returns its path."""
    lines = []
    for line in (SITE.parent / f"{name}.scenario.ini").read_text().splitlines():
        key = line.split("=")[0].strip()
        if key in keys:
            if keys[key] is None:
                continue
            line = f"{key} = {keys[key]}"
        elif key == "site":
            line = f"site = {SITE}"
        lines.append(line)
    path = tmp_path / f"{name}-edited.scenario.ini"
    path.write_text("\n".join(lines) + "\n")
    return path


def warnings(p):
    """The daemon's warnings, in order, without their "warning: " prefix."""
    return [line[len("warning: "):] for line in p.stderr.splitlines() if line.startswith("warning: ")]


def errors(est, truth):
    xt = np.interp(est["t_us"], truth["t_us"], truth["x_m"])
    yt = np.interp(est["t_us"], truth["t_us"], truth["y_m"])
    t_sim = np.interp(est["t_us"], truth["t_us"], truth["t_sim_s"])
    return t_sim, np.hypot(est["x_m"] - xt, est["y_m"] - yt)


def test_kidnap_resets_and_recovers(bridge_bin, tmp_path):
    log, truth_path = run_sim(tmp_path, "kidnap", 75)
    p, est, stats = replay(bridge_bin, log, tmp_path)
    truth = np.genfromtxt(truth_path, delimiter=",", names=True)
    t_sim, err = errors(est, truth)
    before = (t_sim > 40) & (t_sim < 59.5)
    assert np.all(est["reset_counter"][before] == 0)
    assert np.percentile(err[before], 95) < 0.1
    # carried 2 m at 60 s: the reset counter goes up and the error is back
    # under 0.1 m within 5 beacon cycles of the kidnap's end
    assert est["reset_counter"][-1] >= 1
    assert stats["estimator_resets"] >= 1
    back = t_sim > 61.0 + 5 * BEACON_CYCLE_S
    assert np.all(err[back] < 0.1), float(err[back].max())
    assert "re-initialised" in p.stderr or "restarted" in p.stderr


@pytest.mark.parametrize("site, seed", [("big-site", 1), ("big-site", 4), ("hall", 13), ("hall", 15)])
def test_kidnap_on_a_large_site_restarts_within_seconds(bridge_bin, tmp_path, site, seed):
    """The 30 m site (12 beacons heard to 15 m, beacon 1 mostly out of hearing) and the 24 m hall,
    carried 2 m at 60 s: the persistent-rejection watch restarts the filter within 2 s and it
    stays within 0.2 m from 65 s on (0.02-0.10 m measured on these seeds).
    Before, a pending double-pulse conflict held the restart off. On the 30 m site it was
    another beacon's floor echo, which nothing cleared with beacon 1 unheard: the filter coasted
    2 m off for 8 s, published converged, then walked in (back under 0.1 m after 11-28 s on 20
    seeds; 27 s on seed 4). In the hall a floor echo at the robot's new place mimicked beacon 1's
    double pulse in another beacon's slot every cycle, until every arrival of the watch's window
    was rejected (then it restarts): seed 13 restarted after 10.9 s and was 1.3 m off after
    65 s, seed 15 never restarted (seed 12: test_kidnap_in_the_hall_restarts_whatever_double_pulse_is_pending)."""
    log, truth_path = run_sim(tmp_path, str(kidnap_scenario(tmp_path, site)), 75, seed=seed)
    p, est, stats = replay(bridge_bin, log, tmp_path, site=SITE.parent / f"{site}.ini")
    truth = np.genfromtxt(truth_path, delimiter=",", names=True)
    t_sim, err = errors(est, truth)
    before = (t_sim > 40) & (t_sim < 59.5)
    assert np.all(est["reset_counter"][before] == 0)
    assert np.percentile(err[before], 95) < 0.1
    assert stats["snapshot_restarts"] == 1 and est["reset_counter"][-1] == 1, stats
    restarted = t_sim[np.flatnonzero(est["reset_counter"] == 1)[0]]
    assert 60.0 < restarted < 62.0, restarted
    back = t_sim > 65.0
    assert np.all(err[back] < 0.2), float(err[back].max())


@pytest.mark.parametrize("cut, seed", [(True, 6), (True, 15), (False, 12)])
def test_kidnap_in_the_hall_restarts_whatever_double_pulse_is_pending(bridge_bin, tmp_path, cut, seed):
    """The hall, carried 2 m at 60 s (the scenario cut to 75 s, other noise, or the 120 s one run
    for 75 s as above): a floor echo at the robot's new place mimics beacon 1's double pulse in
    another beacon's slot every cycle, so a double-pulse conflict is always pending and the
    persistent-rejection restart waited for it. It now waits at most one window of arrivals
    (12): a beacon controller's restart, what it waits for, is confirmed or cleared by the next
    beacon 1. Restarted after 2.0, 2.0 and 2.6 s, within 0.25 m from 65 s on (0.15, 0.20 and
    0.22 m measured). Before, it waited until every arrival of the window was rejected: 10.4,
    8.5 and 10.4 s, while the filter, sigma 5 cm, walked in from 2 m off on the one or two
    arrivals in twelve it still fused (1.27, 0.58 and 0.66 m off after 65 s)."""
    scenario = kidnap_scenario(tmp_path, "hall", 75 if cut else None)
    log, truth_path = run_sim(tmp_path, str(scenario), 75, seed=seed)
    p, est, stats = replay(bridge_bin, log, tmp_path, site=SITE.parent / "hall.ini")
    truth = np.genfromtxt(truth_path, delimiter=",", names=True)
    t_sim, err = errors(est, truth)
    assert stats["snapshot_restarts"] == 1 and est["reset_counter"][-1] == 1, stats
    restarted = t_sim[np.flatnonzero(est["reset_counter"] == 1)[0]]
    assert 60.0 < restarted < 63.0, restarted
    back = t_sim > 65.0
    assert np.all(err[back] < 0.25), float(err[back].max())


def test_kidnap_in_the_hall_restart_is_not_undone_by_a_misnumbering_sequencer(bridge_bin, tmp_path):
    """The hall, carried 2 m at 60 s, the run 75 s long (other noise than the test above; seed 5):
    the persistent-rejection restart 1 s after the kidnap is right, then the sequencer, without
    the hint while the filter converges, numbers every pulse three slots off (innovations of
    about -0.47 s, against flights of at most 47 ms). Those are numbering errors, and the
    sequencer re-synchronises, once the restart knows its firing time, not only once the
    filter converges: one restart, and the robot stays within 0.25 m from 62 s on.
    Before, they were plain rejections: a second restart fitted them 13.7 m away, published
    converged 13 m off for 4.5 s, and a third ended 5 m off."""
    scenario = kidnap_scenario(tmp_path, "hall", 75)
    log, truth_path = run_sim(tmp_path, str(scenario), 75, seed=5)
    p, est, stats = replay(bridge_bin, log, tmp_path, site=SITE.parent / "hall.ini")
    truth = np.genfromtxt(truth_path, delimiter=",", names=True)
    t_sim, err = errors(est, truth)
    assert stats["snapshot_restarts"] == 1 and est["reset_counter"][-1] == 1, stats
    assert stats["numbering_errors"] >= 2 and stats["sequencer_resyncs"] >= 1, stats
    back = t_sim > 62.0
    assert np.all(err[back] < 0.25), float(err[back].max())


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_kidnap_with_a_turn_recovers_position_and_heading(bridge_bin, tmp_path, seed):
    """Carried 7.5 m and turned 180 degrees at 60 s (kidnap with dtheta): the
    filter re-starts once, from the firings the old state could not explain,
    with its heading from the ring, and is back under 0.1 m and 0.2 rad
    within 10 beacon cycles. (Over seeds 1-8: one reset on 7 of them, two on
    one; position back within 1.0 to 4.3 s. When the restart's snapshot
    still mixed the pulses heard before and after the carry it took 2 or 3
    resets on 7 of the 8, and 2.3 to 4.7 s.)"""
    scenario = tmp_path / "kidnap-turn.scenario.ini"
    text = (SITE.parent / "kidnap.scenario.ini").read_text()
    assert "kidnap = 60, 0.0, 2.0" in text
    scenario.write_text(text.replace("site = kleeman-lab.ini", f"site = {SITE}")
                        .replace("kidnap = 60, 0.0, 2.0", "kidnap = 60, 6.0, 4.5, 180"))
    log, truth_path = run_sim(tmp_path, str(scenario), 80, seed=seed)
    p, est, stats = replay(bridge_bin, log, tmp_path)
    truth = np.genfromtxt(truth_path, delimiter=",", names=True)
    t_sim, err = errors(est, truth)
    th_true = np.interp(est["t_us"], truth["t_us"], np.unwrap(truth["theta_rad"]))
    err_th = np.abs(np.angle(np.exp(1j * (est["theta_rad"] - th_true))))
    before = (t_sim > 40) & (t_sim < 59.5)
    assert np.all(est["reset_counter"][before] == 0)
    assert np.percentile(err[before], 95) < 0.1
    assert est["reset_counter"][-1] == 1
    just_after = (t_sim >= 60) & (t_sim < 62)
    assert np.max(err_th[just_after]) > 2.5          # it really was turned round
    settled = t_sim >= 60 + 10 * BEACON_CYCLE_S
    assert settled.sum() > 100
    assert np.max(err[settled]) < 0.1, np.max(err[settled])
    assert np.max(err_th[settled]) < 0.2, np.max(err_th[settled])


def test_encoder_silence_reported_and_bridged(bridge_bin, tmp_path):
    log, truth_path = run_sim(tmp_path, "encoder-silence", 45)
    p, est, stats = replay(bridge_bin, log, tmp_path)
    truth = np.genfromtxt(truth_path, delimiter=",", names=True)
    t_sim, err = errors(est, truth)
    assert "encoders silent" in p.stderr
    # the scenario silences the encoder node from 20.5 s to 25.5 s
    assert "encoders back after 5.0 s" in p.stderr
    assert stats["encoder_gaps"] == 1
    # estimates keep coming through the silence (pulses, constant velocity)
    silent = (t_sim > 20.7) & (t_sim < 25.3)
    assert silent.sum() >= 25
    assert np.all(err[silent] < 0.25), float(err[silent].max())
    after = t_sim > 28.5
    assert np.percentile(err[after], 95) < 0.1
    assert stats["estimator_resets"] == 0


def test_echo_storm_detected_estimate_holds(bridge_bin, tmp_path):
    log, truth_path = run_sim(tmp_path, "echo-storm", 40)
    p, est, stats = replay(bridge_bin, log, tmp_path)
    truth = np.genfromtxt(truth_path, delimiter=",", names=True)
    t_sim, err = errors(est, truth)
    assert "echo storm" in p.stderr
    # echoes (later arrivals of a firing) are counted, never fused: left
    # out by the sequencer's tracking windows (spurious) once the filter has
    # converged, skipped as repeats before
    assert stats["repeats_skipped"] + stats["sequencer_spurious"] > 100
    keep = t_sim > 20
    assert np.sqrt(np.mean(err[keep] ** 2)) < 0.1
    assert stats["estimator_resets"] == 0


def test_beacon1_outage_numbering_holds(bridge_bin, tmp_path):
    """Beacon 1 (the double pulse that anchors the sequencer) and beacon 4
    silent from 40 s to 60 s: the numbering is kept from the filter's
    firing times, no re-initialisation, the error stays small."""
    scn = scenario_with(tmp_path, "beacon-outage", {"beacon_outage": "40, 20, 1, 4", "duration_s": "70"})
    log, truth_path = run_sim(tmp_path, str(scn), 70)
    p, est, stats = replay(bridge_bin, log, tmp_path)
    truth = np.genfromtxt(truth_path, delimiter=",", names=True)
    t_sim, err = errors(est, truth)
    assert "beacon 1 lost" in p.stderr and "beacon 1 back" in p.stderr
    keep = t_sim > 20
    assert np.max(err[keep]) < 0.15, float(np.max(err[keep]))
    assert stats["estimator_resets"] == 0


def renumbered_once(p, est, stats, truth_path):
    """The run's start renumbered the pulses once from their geometry (one STATUSTEXT,
    sequencer.renumbered 1) and nothing re-initialised the filter; returns (t_sim, err)."""
    truth = np.genfromtxt(truth_path, delimiter=",", names=True)
    assert p.stderr.count("renumbered by geometry") == 1, p.stderr
    assert stats["sequencer"]["renumbered"] == 1
    assert stats["estimator_resets"] == 0
    assert np.all(est["reset_counter"] == 0)
    return errors(est, truth)


@pytest.mark.parametrize("seed", [1, 5])
def test_switched_on_where_beacon1_is_not_heard(bridge_bin, tmp_path, seed):
    """two-rooms-east: switched on in the east room, where the partition hides beacon 1 and
    beacon 7's floor echo, 3 ms behind it, passes for the double pulse: the sequencer numbers
    every beacon six places off (seven on some seeds). The filter's start renumbers from the
    pulses' geometry (one STATUSTEXT saying so, sequencer.renumbered 1), starts within 0.2 m
    and stays on the robot. Before it: started 10 m off on every seed, 2 of 4 runs lost for
    good; seed 5 started from four beacons, whose wrong fix passed the residual test 7 m outside
    the room, until a start of four was checked for its numbering too."""
    log, truth_path = run_sim(tmp_path, "two-rooms-east", 60, seed=seed)
    site = SITE.parent / "two-rooms.ini"
    p, est, stats = replay(bridge_bin, log, tmp_path, site=site)
    t_sim, err = renumbered_once(p, est, stats, truth_path)
    assert err[0] < 0.2, float(err[0])
    assert np.all(err[t_sim > 10] < 0.1), float(err[t_sim > 10].max())


@pytest.mark.parametrize("seed", [2, 3])
def test_beacon1_dead_from_power_on(bridge_bin, tmp_path, seed):
    """beacon1-dead: kleeman-lab with beacon 1 silent from power-on, so its double pulse, which
    marks the cycle, is never heard; kleeman-lab's beacons are point-symmetric (a numbering three
    places off fits every pulse half a turn away). The localizer numbers the pulses from beacon
    1's signature (a firing three receivers heard without the double pulse is not beacon 1's) and
    their geometry: one STATUSTEXT saying so, no re-initialisation, within 0.3 m at the start (it
    starts on the move, about 10 s in: 0.11-0.29 m over 20 seeds), then on the robot (from 3 s
    after the start: RMS under 40 mm, never 0.15 m off). Before it: seed 2 started at the
    half-turn twin, 9.5 m off at the end, confident (converged); seed 3 never started."""
    log, truth_path = run_sim(tmp_path, "beacon1-dead", 60, seed=seed)
    p, est, stats = replay(bridge_bin, log, tmp_path)
    t_sim, err = renumbered_once(p, est, stats, truth_path)
    assert err[0] < 0.3, float(err[0])
    settled = t_sim > t_sim[0] + 3
    assert np.sqrt(np.mean(err[settled] ** 2)) < 0.04, float(np.sqrt(np.mean(err[settled] ** 2)))
    assert np.all(err[settled] < 0.15), float(err[settled].max())


@pytest.mark.parametrize("seed", [1, 2])
def test_controller_restarts_keep_the_pose(bridge_bin, tmp_path, seed):
    """controller-restart: the beacon controller restarts at 40 s (0.7 s off, less than a beacon
    cycle: beacon 1 then fires 163 ms after the slot the filter expects, beyond any flight) and at
    80 s (1.234 s off, more than a cycle). Each silence swallowed the firings of beacons being heard
    (the first about four, the second a whole cycle): the daemon tells the localizer the firing
    times are known to half a cycle only (a NOTICE "beacons silent 0.8 s: firing times re-learnt",
    then "... 1.4 s ...") and the next arrivals, numbered from beacon 1's double pulse, re-anchor
    them. The pose is kept: no re-initialisation, no re-synchronisation from the stale firing
    times, no timing jump left for the localizer's watch, no echo storm called, RMS under 40 mm
    after the start and never 0.15 m off. Before the watch: on seed 1 the first restart's wrongly
    numbered pulses restarted the filter 3.5 m off (two restarts, 3 s lost); on 20 seeds ratio
    10.8 (1.101 with the watch alone, 1.058 with the second restart re-learnt, 1.028 now)."""
    log, truth_path = run_sim(tmp_path, "controller-restart", 90, seed=seed)
    p, est, stats = replay(bridge_bin, log, tmp_path)
    truth = np.genfromtxt(truth_path, delimiter=",", names=True)
    t_sim, err = errors(est, truth)
    relearnt = re.findall(r"info: beacons silent (\d\.\d) s: firing times re-learnt", p.stderr)
    assert relearnt == ["0.8", "1.4"], p.stderr
    assert warnings(p) == [] and "echo storm" not in p.stderr, p.stderr
    assert stats["timing_jumps"] == 0
    assert stats["estimator_resets"] == 0 and stats["sequencer_resyncs"] == 0
    assert np.all(est["reset_counter"] == 0)
    late = t_sim > 20
    assert np.sqrt(np.mean(err[late] ** 2)) < 0.04, float(np.sqrt(np.mean(err[late] ** 2)))
    assert np.all(err[late] < 0.15), float(err[late].max())


def one_controller_restart(bridge_bin, tmp_path, pause_s, duration_s, seed):
    """controller-restart with one restart, at 60 s for pause_s, replayed: (the daemon's run,
    its stats, each estimate's simulation time and position error)."""
    scn = scenario_with(tmp_path, "controller-restart",
                        {"controller_restart": f"60, {pause_s}", "controller_restart2": None})
    log, truth_path = run_sim(tmp_path, str(scn), duration_s, seed=seed)
    p, est, stats = replay(bridge_bin, log, tmp_path)
    t_sim, err = errors(est, np.genfromtxt(truth_path, delimiter=",", names=True))
    return p, stats, t_sim, err


@pytest.mark.parametrize("seed", [10, 16])
def test_controller_restart_after_seconds_relearns_the_firing_times(bridge_bin, tmp_path, seed):
    """The beacon controller off for 5 s at 60 s (a slow reboot): one warning that no pulse came,
    and when pulses come again the firing times are re-learnt from them (the localizer told they
    are known to half a cycle; the sequencer locks on beacon 1's double pulse again): no
    re-initialisation, no re-synchronisation, never 0.15 m off after the start (the wheels alone
    carried the pose 5 s: 0.124 and 0.144 m). Before (the timing watch alone) both seeds restarted
    the filter from wrongly numbered pulses, 3.5 and 5.5 m off for the rest of the run; on 20
    seeds 3 such runs (6 before the watch took fused signed firings), none now."""
    p, stats, t_sim, err = one_controller_restart(bridge_bin, tmp_path, 5.0, 90, seed)
    assert "no pulse heard for 2.0 s" in warnings(p), p.stderr
    assert re.search(r"info: pulses again after 5\.\d s: firing times re-learnt", p.stderr), p.stderr
    assert stats["estimator_resets"] == 0 and stats["sequencer_resyncs"] == 0, stats
    assert stats["timing_jumps"] == 0
    late = t_sim > 20
    assert np.all(err[late] < 0.15), float(err[late].max())


def test_silence_where_beacon_1_is_not_heard_keeps_the_firing_times(bridge_bin, tmp_path):
    """two-rooms-east (beacon 1 never heard) with every beacon off for 1.5 s at 60 s: the firing
    times are not thrown away (nothing but them numbers the arrivals there: beacon 1's double
    pulse is never heard), and the pose is kept. With the re-learning applied there too, 3 of 6
    runs restarted the filter and ended 7-11 m off (seeds 1, 4, 5)."""
    outage = "faults.beacon_outage=60, 1.5, " + ", ".join(str(b) for b in range(1, 11))
    log, truth_path = run_sim(tmp_path, "two-rooms-east", 90, seed=4, sim_args=["--set", outage])
    p, est, stats = replay(bridge_bin, log, tmp_path, site=SITE.parent / "two-rooms.ini")
    truth = np.genfromtxt(truth_path, delimiter=",", names=True)
    t_sim, err = errors(est, truth)
    assert "firing times re-learnt" not in p.stderr, p.stderr
    assert stats["estimator_resets"] == 0, stats
    assert np.all(err[t_sim > 20] < 0.1), float(err[t_sim > 20].max())


@pytest.mark.parametrize("seed", [1, 2])
def test_sensor_node_restarts_keep_the_pose(bridge_bin, tmp_path, seed):
    """node-restart: the robot's receiver array restarts at 40 s (0.3 s off) and 100 s (1.5 s
    off), its wheel encoders at 80 s (0.2 s off): each comes back with its clock, its rolling
    counters and (the encoders) its ticks from 0. The daemon warns of each restart, carries the
    receiver clock's timeline on (the localizer told the firing times are known to 1 ms), takes
    the encoders' new counts as a new reference, counts no frame lost (the counters started over,
    nothing went missing) and calls no beacon lost (no pulse at all came: the receiver was off);
    the pose is kept: no re-initialisation, RMS under 40 mm after the start, never 0.12 m off
    (0.069 and 0.098 m on these seeds). Before: 18 and 19 frames counted lost, beacons 2-4 (and
    5) called lost in the 1.5 s pause."""
    log, truth_path = run_sim(tmp_path, "node-restart", 110, seed=seed)
    p, est, stats = replay(bridge_bin, log, tmp_path)
    truth = np.genfromtxt(truth_path, delimiter=",", names=True)
    t_sim, err = errors(est, truth)
    assert warnings(p) == ["receiver node clock restarted", "encoder node clock restarted",
                           "receiver node clock restarted"], p.stderr
    assert stats["node_restarts"] == 3 and stats["lost_by_counter"] == 0, stats
    assert stats["estimator_resets"] == 0 and stats["timing_jumps"] == 0
    assert stats["sequencer_resyncs"] == 0
    assert np.all(est["reset_counter"] == 0)
    late = t_sim > 20
    assert np.sqrt(np.mean(err[late] ** 2)) < 0.04, float(np.sqrt(np.mean(err[late] ** 2)))
    assert np.all(err[late] < 0.12), float(err[late].max())


def test_receiver_off_for_seconds_is_one_warning(bridge_bin, tmp_path):
    """The receiver array off for 5 s (node-restart's second restart made longer): one warning
    that no pulse came, none of the six beacons called lost (it was not they), a notice when
    pulses come again, and the pose back within 0.1 m 3 s after the receiver is back (the wheels
    carried it 5 s). Before: beacons 2-6 called lost one by one."""
    scn = scenario_with(tmp_path, "node-restart", {"node_restart3": "100, 5, 1"})
    log, truth_path = run_sim(tmp_path, str(scn), 110, seed=1)
    p, est, stats = replay(bridge_bin, log, tmp_path)
    truth = np.genfromtxt(truth_path, delimiter=",", names=True)
    t_sim, err = errors(est, truth)
    assert warnings(p) == ["receiver node clock restarted", "encoder node clock restarted",
                           "no pulse heard for 2.0 s", "receiver node clock restarted"], p.stderr
    assert p.stderr.count("info: pulses again after 5.") == 1, p.stderr
    assert stats["estimator_resets"] == 0 and stats["lost_by_counter"] == 0
    assert np.all(err[t_sim > 108] < 0.1), float(err[t_sim > 108].max())


@pytest.mark.parametrize("scenario, site, node, name, at_s, duration_s, extra", [
    ("eurobot", "eurobot.ini", 3, "bearing sensor", 5.0, 12, ()),
    ("marvelmind", "marvelmind.ini", 4, "range receiver", 30.0, 45, ()),
    # the sonar ring's filter starts from a known pose (the path's start, 2 cm, 1 deg)
    ("hoppenot-room", "hoppenot-room.ini", 5, "sonar ring", 15.0, 30,
     ("--initial-pose", "1.0,1.0,0,0.02,1")),
    ("thermometer-still", "kleeman-thermometer.ini", 6, "thermometer", 50.0, 65, ()),
])
def test_every_node_kinds_restart_is_one_warning(bridge_bin, tmp_path, scenario, site, node, name,
                                                  at_s, duration_s, extra):
    """The other sensor nodes restart too (off 0.5 s, then their clock and counters from 0): one
    warning naming the node, no frame counted lost (before: 20, 5, 10 and 25, its counters' step),
    no re-initialisation, and the pose within 0.1 m of the truth at the end."""
    log, truth_path = run_sim(tmp_path, scenario, duration_s, seed=1,
                              sim_args=["--set", f"faults.node_restart={at_s}, 0.5, {node}"])
    p, est, stats = replay(bridge_bin, log, tmp_path, *extra, site=SITE.parent / site)
    truth = np.genfromtxt(truth_path, delimiter=",", names=True)
    t_sim, err = errors(est, truth)
    assert p.stderr.count(f"{name} clock restarted") == 1, p.stderr
    assert stats["node_restarts"] == 1 and stats["lost_by_counter"] == 0, stats
    assert stats["estimator_resets"] == 0 and np.all(est["reset_counter"] == est["reset_counter"][0])
    assert np.all(err[t_sim > duration_s - 2] < 0.1), float(err[t_sim > duration_s - 2].max())


def _apart_m(est0, est) -> float:
    """How far (m) the estimates `est` are at most from `est0`, each time's latest row of one
    against the latest row of the other within 5 us (a node time mapped a few us off)."""
    def latest(e):
        last = np.r_[e["t_us"][1:] != e["t_us"][:-1], True]
        return e["t_us"][last], e["x_m"][last], e["y_m"][last]
    t0, x0, y0 = latest(est0)
    t1, x1, y1 = latest(est)
    order = np.argsort(t1, kind="stable")
    j = np.clip(np.searchsorted(t1[order], t0), 1, len(t1) - 1)
    j = np.where(np.abs(t1[order][j - 1] - t0) <= np.abs(t1[order][j] - t0), j - 1, j)
    k = order[j]
    same = np.abs(t1[k] - t0) <= 5
    # a hold adds or drops a few rows (updates batched or split otherwise): 97 % measured
    assert same.mean() > 0.95, f"only {same.mean():.1%} of the rows in both runs"
    return float(np.max(np.hypot(x1[k] - x0, y1[k] - y0)[same]))


@pytest.mark.parametrize("scenario, site, duration_s, holds, kinds", [
    ("kleeman-lab", "kleeman-lab.ini", 40, [(15, 1.5), (25, 0.7), (32, 4.0)],
     ("pulse_detection", "wheel_encoders")),
    ("eurobot", "eurobot.ini", 12, [(4, 1.0), (7, 0.6)], ("bearing", "wheel_encoders")),
    ("marvelmind", "marvelmind.ini", 45, [(15, 1.5), (30, 0.8)], ("range", "wheel_encoders")),
])
def test_backlog_delivered_late_is_not_a_restart(bridge_bin, tmp_path, scenario, site, duration_s,
                                                 holds, kinds):
    """Every node's frames held up to 4 s and then delivered at once (the simulator's [faults]
    backlog: a USB or Ethernet gateway, a starved relay): each frame keeps its own stamp (node_clock.h, "late"), counted
    late_frames, and the estimates are those of the same frames never held: the same to 0.1 mm
    on eurobot and marvelmind, within 12 mm on kleeman-lab, where a hold longer than a beacon
    cycle is a silence the firing times are re-learnt after (the bridge cannot know a backlog is
    coming). Before, a hold over 0.5 s was taken for the restart of every node's clock,
    re-anchored a hold late."""
    run_dir = tmp_path / "as-sent"
    run_dir.mkdir()
    log0, _ = run_sim(run_dir, scenario, duration_s, seed=1)
    backlogs = [f"faults.backlog{i}={start}, {hold}" for i, (start, hold) in enumerate(holds)]
    log, truth_path = run_sim(tmp_path, scenario, duration_s, seed=1,
                              sim_args=[a for b in backlogs for a in ("--set", b)])
    site_path = SITE.parent / site
    _, est0, _ = replay(bridge_bin, log0, run_dir, site=site_path)
    p, est, stats = replay(bridge_bin, log, tmp_path, site=site_path)
    assert "clock restarted" not in p.stderr, p.stderr
    assert stats["node_restarts"] == 0 and stats["estimator_resets"] == 0, stats
    assert all(stats["late_frames_per_frame"][k] > 0 for k in kinds), stats["late_frames_per_frame"]
    assert stats["late_frames"] == sum(stats["late_frames_per_frame"].values())
    apart = _apart_m(est0, est)
    assert apart < 0.02, apart
    truth = np.genfromtxt(truth_path, delimiter=",", names=True)
    t_sim, err = errors(est, truth)
    assert np.all(err[t_sim > duration_s - 2] < 0.05), float(err[t_sim > duration_s - 2].max())


@pytest.mark.parametrize("pause_s, seed, silent", [(0.8, 2, "0.9"), (0.65, 15, "0.7")])
def test_controller_restart_shorter_than_a_cycle_relearns(bridge_bin, tmp_path, pause_s, seed,
                                                          silent):
    """The controller off for less than a beacon cycle (0.9 s here) at 60 s: the silence, shorter
    than a cycle, swallowed the firings of three beacons or more that were being heard (fused in
    the two cycles before), so it is the controller's, not the beacons': the firing times are
    re-learnt as after a whole cycle (one NOTICE), no warning, no re-initialisation, no timing jump
    left, never 0.1 m off after the start (0.076 and 0.063 m). Before (a whole cycle's silence
    only, the timing watch for the rest) the 0.8 s pause's seed 2 ended 9.9 m off (persistent
    rejection, then the filter restarted on wrongly numbered pulses) and the 0.65 s pause's seed
    15 restarted once, 0.20 m off; on 20 seeds ratio 45.1 (one run lost) and 1.306, now 0.973 and
    1.052."""
    p, stats, t_sim, err = one_controller_restart(bridge_bin, tmp_path, pause_s, 75, seed)
    assert re.findall(r"info: beacons silent (\d\.\d) s: firing times re-learnt", p.stderr) == [silent], p.stderr
    assert warnings(p) == [], p.stderr
    assert stats["timing_jumps"] == 0 and stats["estimator_resets"] == 0, stats
    assert stats["sequencer_resyncs"] == 0
    late = t_sim > 20
    assert np.all(err[late] < 0.1), float(err[late].max())


@pytest.mark.parametrize("seed", [4, 5])
def test_controller_restart_of_two_firings_is_voted_at_once(bridge_bin, tmp_path, seed):
    """The controller off 0.3 s at 60 s: the silence swallows two firings at most, as a beacon or
    two out of their beams would, and the firing times are not thrown away; the arrivals after it
    are off them by one common move, and the firings vote it from the filter's pose
    (bridge/timing_vote.c): after four of them the firing times move (one STATUSTEXT "beacon
    firing times jumped"), the pose kept, no re-initialisation, a handful of arrivals rejected,
    never 0.1 m off after the start (0.073 and 0.091 m). Before the vote the localizer's timing watch did it about 2 s
    after the restart (a warning that no pulse was fused for 2 s; 0.093 and 0.092 m off)."""
    p, stats, t_sim, err = one_controller_restart(bridge_bin, tmp_path, 0.3, 75, seed)
    assert warnings(p) == ["beacon firing times jumped (controller restart): t0 re-anchored"], p.stderr
    assert "firing times re-learnt" not in p.stderr, p.stderr
    assert stats["timing_jumps"] == 1 and stats["estimator_resets"] == 0
    assert stats["pulses_rejected"] <= 12, stats["pulses_rejected"]
    late = t_sim > 20
    assert np.all(err[late] < 0.1), float(err[late].max())


@pytest.mark.parametrize("scenario, pause_s, seed", [("hall", 1.56, 1), ("big-site", 0.3, 1)])
def test_controller_restart_out_of_beacon_1s_hearing_is_voted(bridge_bin, tmp_path, scenario,
                                                               pause_s, seed):
    """A large site whose robot is out of beacon 1's hearing when the controller restarts at 60 s
    (the hall, 24 m, off 1.3 cycles; the 30 m site, 15 m hearing range, off 0.3 s): no double pulse
    says which beacon fires, so neither the localizer's timing watch nor the re-learning after a
    silence applies. The firings after the restart vote, each from the filter's pose, where the
    firing times moved (bridge/timing_vote.c): once four firings of three beacons agree on one move,
    with three more than any other, the firing times move by it (one "beacon firing times jumped"),
    no re-initialisation, never 0.2 m off after the start (0.106 and 0.084 m). Before: the runs
    ended 6.1 m and 18.1 m off (the filter restarted on wrongly numbered pulses)."""
    log, truth_path = run_sim(tmp_path, scenario, 75, seed=seed,
                              sim_args=["--set", f"faults.controller_restart=60, {pause_s}"])
    p, est, stats = replay(bridge_bin, log, tmp_path, site=SITE.parent / f"{scenario}.ini")
    t_sim, err = errors(est, np.genfromtxt(truth_path, delimiter=",", names=True))
    assert p.stderr.count("beacon firing times jumped (controller restart)") == 1, p.stderr
    assert "firing times re-learnt" not in p.stderr, p.stderr
    assert stats["timing_jumps"] == 1 and stats["estimator_resets"] == 0, stats
    late = t_sim > 20
    assert np.all(err[late] < 0.2), float(err[late].max())


def test_temperature_ramp_speed_of_sound_followed(bridge_bin, tmp_path):
    """15 -> 25 degC over 120 s, the first 90 s run (+7.5 degC), the checks
    of the live suite's ramp case, moved here: nothing in them needs a live
    bus. The truth's speed of sound moves by > 2 m/s; after 20 s the
    estimate follows it within 1 m/s rms,
    >= 95 % of positions lie inside their reported 3 sigma, and the position
    rms over the last 10 s is under 0.1 m, with no re-initialisation."""
    log, truth_path = run_sim(tmp_path, "temperature-ramp", 90)
    p, est, stats = replay(bridge_bin, log, tmp_path)
    truth = np.genfromtxt(truth_path, delimiter=",", names=True)
    assert truth["sos_mps"].max() - truth["sos_mps"].min() > 2.0, "the ramp did not move s"
    t_sim, err = errors(est, truth)
    late = t_sim > 20
    sos_err = est["sos_mps"] - np.interp(est["t_us"], truth["t_us"], truth["sos_mps"])
    sos_rms = float(np.sqrt(np.mean(sos_err[late] ** 2)))
    assert sos_rms < 1.0, f"speed of sound rms error {sos_rms:.2f} m/s during the ramp"
    ex = est["x_m"] - np.interp(est["t_us"], truth["t_us"], truth["x_m"])
    ey = est["y_m"] - np.interp(est["t_us"], truth["t_us"], truth["y_m"])
    vxx, vxy, vyy = est["var_x_m2"], est["cov_xy_m2"], est["var_y_m2"]
    # d^2 = e^T P^-1 e for the 2x2 position block.
    d2 = (vyy * ex * ex - 2 * vxy * ex * ey + vxx * ey * ey) / (vxx * vyy - vxy * vxy)
    inside = float(np.mean(np.sqrt(d2[late]) <= 3.0))
    assert inside >= 0.95, f"only {inside:.1%} of estimates inside their 3 sigma"
    last = t_sim >= t_sim[-1] - 10.0
    assert np.sqrt(np.mean(err[last] ** 2)) < 0.1
    assert stats["estimator_resets"] == 0


def _rewrite_frames(log, can_id: str, every: int, rewrite) -> int:
    """Every `every`-th frame of id `can_id` (hex, as candump writes it) of the candump log
    gets its payload changed in place by rewrite(bytearray): returns how many were changed."""
    lines = log.read_text().splitlines()
    changed = seen = 0
    for i, line in enumerate(lines):
        parts = line.split()
        if len(parts) < 3 or not parts[2].startswith(can_id + "#"):
            continue
        seen += 1
        if seen % every:
            continue
        data = bytearray.fromhex(parts[2][len(can_id) + 1:])
        rewrite(data)
        parts[2] = can_id + "#" + data.hex().upper()
        lines[i] = " ".join(parts)
        changed += 1
    log.write_text("\n".join(lines) + "\n")
    return changed


# --------------------------------------------------------------------------
# The air thermometer: AIR_TEMPERATURE frames move the speed of sound by the
# air's change (lib aid_thermometer.h).
# --------------------------------------------------------------------------

THERMO_SITE = SITE.parent / "kleeman-thermometer.ini"


def _sos_rms_after(est, truth, t0_s: float) -> float:
    t_sim = np.interp(est["t_us"], truth["t_us"], truth["t_sim_s"])
    err = est["sos_mps"] - np.interp(est["t_us"], truth["t_us"], truth["sos_mps"])
    return float(np.sqrt(np.mean(err[t_sim > t0_s] ** 2)))


def _glitch_air_temperature(log, every: int) -> int:
    """Every `every`-th AIR_TEMPERATURE frame of the candump log reads 85 C (a DS18B20's
    power-on value): returns how many were changed."""
    def to_85c(data: bytearray) -> None:
        data[4:6] = (85 * 128).to_bytes(2, "little", signed=True)  # Temperature: bits 32..47
    return _rewrite_frames(log, "170", every, to_85c)


def test_thermometer_carries_a_swing(bridge_bin, tmp_path):
    """thermometer-swing20's first 90 s (10 -> 25 C), replayed twice: on its site the
    thermometer's readings move s with the air (every frame accounted for, none refused) and
    the speed of sound stays within 1 m/s rms after 20 s; on kleeman-lab, which has no
    thermometer, the same frames are counted unexpected and dropped and s lags the swing."""
    log, truth_path = run_sim(tmp_path, "thermometer-swing20", 90)
    truth = np.genfromtxt(truth_path, delimiter=",", names=True)
    p, est, stats = replay(bridge_bin, log, tmp_path, site=THERMO_SITE)
    received = stats["frames_received"]["air_temperature"]
    assert received == pytest.approx(180, abs=2)  # 2 readings a second
    assert (stats["thermometer_fused"] + stats["thermometer_rejected"]
            + stats["thermometer_buffered"] + stats["thermometer_refused"]
            + stats["thermometer_unexpected"] + stats["stale_thermometer_samples"]
            + stats["unmapped_thermometer"]) == received
    assert stats["thermometer_fused"] >= received - 3
    assert stats["thermometer_refused"] == stats["thermometer_rejected"] == 0
    assert "thermo ok" in p.stderr
    with_thermo = _sos_rms_after(est, truth, 20)
    assert with_thermo < 1.0, with_thermo
    p, est, stats = replay(bridge_bin, log, tmp_path)
    assert stats["thermometer_unexpected"] == received
    assert stats["thermometer_fused"] == 0
    without = _sos_rms_after(est, truth, 20)
    assert without > 1.5 * with_thermo, (without, with_thermo)


def test_thermometer_glitches_rejected(bridge_bin, tmp_path):
    """One reading in 20 replaced by 85 C: each glitch rejected, and only it (the reading
    after it is taken against the sensor's model as it was), nothing restarts, s still
    follows."""
    log, truth_path = run_sim(tmp_path, "thermometer-swing20", 60)
    glitches = _glitch_air_temperature(log, 20)
    assert glitches >= 5
    truth = np.genfromtxt(truth_path, delimiter=",", names=True)
    p, est, stats = replay(bridge_bin, log, tmp_path, site=THERMO_SITE)
    assert stats["thermometer_rejected"] == glitches
    assert stats["thermometer_refused"] == 0
    assert stats["thermometer_fused"] >= stats["frames_received"]["air_temperature"] - glitches - 3
    assert stats["estimator_resets"] == 0
    assert _sos_rms_after(est, truth, 20) < 1.0


# --------------------------------------------------------------------------
# Bearings (issue 11): the eurobot table of Vander et al. 2011, a site of
# three bearing beacons and no ultrasonic one.
# --------------------------------------------------------------------------

EUROBOT = SITE.parent / "eurobot.ini"


def _bearing_lines_to_unknown_beacon(log, every: int) -> int:
    """Every `every`-th BEARING frame of the candump log names bearing beacon 7
    (the site has 3; the DBC allows 1..15): returns how many were changed."""
    def beacon_7(data: bytearray) -> None:
        data[4] = (data[4] & 0xF0) | 7  # Beacon: bits 32..35
    return _rewrite_frames(log, "140", every, beacon_7)


def test_eurobot_bearings_only(bridge_bin, tmp_path):
    """The eurobot scenario replayed: the filter starts from the bearings'
    triangulation and follows the robot on bearings and encoders; every
    bearing frame is accounted for; a bearing from a beacon the site does
    not have is counted and dropped."""
    log, truth_path = run_sim(tmp_path, "eurobot", 12)
    unknown = _bearing_lines_to_unknown_beacon(log, 25)
    assert unknown > 5
    p, est, stats = replay(bridge_bin, log, tmp_path, site=EUROBOT)
    truth = np.genfromtxt(truth_path, delimiter=",", names=True)
    # the estimates are on the bearing sensor's clock, the truth's time base
    # on a site without ultrasonic beacons
    assert est["t_us"][0] >= truth["t_us"][0] and est["t_us"][-1] <= truth["t_us"][-1]
    t_sim, err = errors(est, truth)
    assert t_sim[0] < 2.0, "the filter did not start from the bearings"
    keep = t_sim > 2.0
    assert np.sqrt(np.mean(err[keep] ** 2)) < 0.04, float(np.sqrt(np.mean(err[keep] ** 2)))
    assert np.max(err[t_sim > 8.0]) < 0.02  # standing at the end, Vander Fig. 7
    received = stats["frames_received"]["bearing"]
    assert received > 300  # 3 beacons at 10 Hz for 12 s
    assert stats["bearings_unknown_beacon"] == unknown
    assert (stats["bearings_fused"] + stats["bearings_rejected"] + stats["bearings_buffered"]
            + stats["bearings_refused"] + stats["bearings_unknown_beacon"]
            + stats["stale_bearing_samples"] + stats["bearings_unexpected"]
            + stats["unmapped_bearings"]) == received
    assert stats["bearings_refused"] == 0 and stats["bearings_unexpected"] == 0
    assert stats["frames_received"]["pulse_detection"] == 0
    assert stats["estimator_resets"] == 0
    assert "bearings ok" in p.stderr  # the final status line


def test_bearings_on_a_site_without_bearing_beacons(bridge_bin, tmp_path):
    """kleeman-lab has no bearing beacons: the eurobot log's bearing frames
    are counted as unexpected and dropped, its encoder frames still used."""
    log, _ = run_sim(tmp_path, "eurobot", 4)
    p, est, stats = replay(bridge_bin, log, tmp_path)
    assert stats["bearings_unexpected"] == stats["frames_received"]["bearing"] > 50
    assert stats["bearings_fused"] + stats["bearings_buffered"] == 0


def test_initial_pose_starts_the_filter_at_once(bridge_bin, tmp_path):
    """--initial-pose: the filter starts at the first sample from the given pose
    (7 cm off the truth, sigma 7 cm) instead of waiting for a triangulation, its
    first estimate is that pose, its covariance honest, and it converges."""
    log, truth_path = run_sim(tmp_path, "eurobot", 6)
    truth = np.genfromtxt(truth_path, delimiter=",", names=True)
    x0, y0 = float(truth["x_m"][0]) + 0.07, float(truth["y_m"][0])
    heading = float(np.degrees(truth["theta_rad"][0]))
    p, est, stats = replay(bridge_bin, log, tmp_path, "--initial-pose",
                           f"{x0!r},{y0!r},{heading!r},0.07", site=EUROBOT)
    assert "started from the initial pose" in p.stderr
    assert stats["known_starts"] == 1 and stats["estimator_resets"] == 0
    t_sim, err = errors(est, truth)
    assert t_sim[0] < 0.05   # the first sample, not a triangulation a scan or more later
    assert abs(est["x_m"][0] - x0) < 0.01 and abs(est["y_m"][0] - y0) < 0.01
    assert 0.05 < np.sqrt(est["var_x_m2"][0]) < 0.08
    assert np.sqrt(np.mean(err[t_sim > 2.0] ** 2)) < 0.03
    # without it the same log starts later, from the bearings
    p, est2, stats2 = replay(bridge_bin, log, tmp_path, site=EUROBOT)
    assert stats2["known_starts"] == 0 and errors(est2, truth)[0][0] > t_sim[0]


@pytest.mark.parametrize("value", ["1,2,3", "1,2,3,0", "1,2,3,-1", "1,2,3,0.1,0", "a,b,c,d",
                                   "1,2,3,0.1,5,6", "1e5,0,0,0.1", "1,2,nan,0.1"])
def test_initial_pose_bad_values_exit_78(bridge_bin, value):
    p = subprocess.run([str(bridge_bin), "--site", str(EUROBOT), "--replay", "/dev/null",
                        "--initial-pose", value], capture_output=True, text=True, timeout=20)
    assert p.returncode == 78 and f"--initial-pose: '{value}'" in p.stderr, p.stderr


# --------------------------------------------------------------------------
# Ranges (issue 13): the marvelmind room, four fixed range beacons on the
# walls and no other beacon (a range-only site: the filter runs on the range
# receiver's clock, the truth's time base).
# --------------------------------------------------------------------------

MARVELMIND = SITE.parent / "marvelmind.ini"
RANGE_COUNTERS = ("ranges_fused", "ranges_rejected", "ranges_buffered", "ranges_refused",
                  "ranges_unknown_beacon", "ranges_unexpected", "ranges_other_receiver",
                  "ranges_bad_tof", "stale_range_samples", "unmapped_ranges")


def _edit_range_frames(log, every: int, edit) -> int:
    """Apply edit(bytearray) to every `every`-th RANGE frame (0x130) of the
    candump log; returns how many were changed."""
    lines = log.read_text().splitlines()
    changed = seen = 0
    for i, line in enumerate(lines):
        parts = line.split()
        if len(parts) < 3 or not parts[2].startswith("130#"):
            continue
        seen += 1
        if seen % every:
            continue
        data = bytearray.fromhex(parts[2][4:])
        edit(data)
        parts[2] = "130#" + data.hex().upper()
        lines[i] = " ".join(parts)
        changed += 1
    log.write_text("\n".join(lines) + "\n")
    return changed


def test_marvelmind_ranges_only(bridge_bin, tmp_path):
    """The marvelmind scenario replayed: the filter starts from the ranges'
    trilateration and follows the robot on ranges and encoders, near the
    truth and inside its own 3 sigma; every range frame lands in exactly one
    counter; ranges naming a beacon the site does not have (7 of 4), another
    robot's receiver (2) or a zero time of flight are counted and dropped."""
    log, truth_path = run_sim(tmp_path, "marvelmind", 30)

    def beacon7(d):
        d[4] = (d[4] & 0xF0) | 7  # Beacon: bits 32..35

    def receiver2(d):
        d[4] = (d[4] & 0x0F) | 0x20  # Receiver: bits 36..39

    def zero_tof(d):
        d[5] = d[6] = 0  # TimeOfFlight: bits 40..55

    unknown = _edit_range_frames(log, 29, beacon7)
    other = _edit_range_frames(log, 31, receiver2)
    zero = _edit_range_frames(log, 37, zero_tof)
    assert unknown > 10 and other > 10 and zero > 10
    p, est, stats = replay(bridge_bin, log, tmp_path, site=MARVELMIND)
    truth = np.genfromtxt(truth_path, delimiter=",", names=True)
    # the estimates are on the range receiver's clock, the truth's time base
    assert est["t_us"][0] >= truth["t_us"][0] and est["t_us"][-1] <= truth["t_us"][-1]
    t_sim, err = errors(est, truth)
    assert t_sim[0] < 1.0, "the filter did not start from the ranges"
    keep = t_sim > 2.0
    rmse = float(np.sqrt(np.mean(err[keep] ** 2)))
    assert rmse < 0.04, rmse
    # honest covariance: the position error inside 3 sigma of its own
    # (larger axis) almost always
    sigma = np.sqrt(np.maximum(est["var_x_m2"], est["var_y_m2"]))
    inside = float(np.mean(err[keep] < 3 * np.sqrt(2) * sigma[keep]))
    assert inside > 0.95, inside
    received = stats["frames_received"]["range"]
    assert received > 550  # one ping every 50 ms for 30 s
    assert sum(stats[k] for k in RANGE_COUNTERS) == received
    assert stats["ranges_unknown_beacon"] == unknown
    assert stats["ranges_other_receiver"] == other
    # a frame edited twice counts where it stopped first (receiver, then ToF)
    assert stats["ranges_bad_tof"] <= zero and stats["ranges_bad_tof"] >= zero - 2
    assert stats["ranges_fused"] > 0.8 * (received - unknown - other - zero)
    assert stats["ranges_refused"] == 0 and stats["ranges_unexpected"] == 0
    assert stats["stale_range_samples"] == 0 and stats["unmapped_ranges"] == 0
    assert stats["frames_received"]["pulse_detection"] == 0
    assert stats["estimator_resets"] == 0
    assert "ranges ok" in p.stderr  # the final status line


def test_ranges_on_a_site_without_range_beacons(bridge_bin, tmp_path):
    """kleeman-lab has no range beacons: the marvelmind log's range frames
    are counted as unexpected and dropped."""
    log, _ = run_sim(tmp_path, "marvelmind", 4)
    p, est, stats = replay(bridge_bin, log, tmp_path)
    assert stats["ranges_unexpected"] == stats["frames_received"]["range"] > 50
    assert stats["ranges_fused"] + stats["ranges_buffered"] == 0


# The marvelmind room's robot placed facing `heading_deg` (the site assumes 0): it stands 5 s,
# drives 3 m straight, turns right round a 0.5 m arc, 2 m, another, 3 m (inside the room).
FACING = {0: ("1.5, 1.5, 0", ["arc 90 0.5", "straight 2.0", "arc 90 0.5", "straight 3.0"]),
          90: ("1.5, 0.5, 90", ["wait 1", "straight 1.0", "arc -90 0.5", "straight 3.0"]),
          180: ("4.5, 1.5, 180", ["arc -90 0.5", "straight 2.0", "arc -90 0.5", "straight 3.0"])}


@pytest.mark.parametrize("heading_deg", [0, 90, 180])
def test_range_robot_learns_its_heading_from_the_track(bridge_bin, tmp_path, heading_deg):
    """A range-only robot does not know its heading until it moves (lib aid_range.cpp, "the
    heading from the track"). From its first motion the ranges score a ring of headings; the
    estimate is published not converged (quality -1) until one is decided, under 2 s later; then
    every converged estimate lies within 0.1 m of the truth, those of the 3 s after the decision
    97 % inside their own 3 sigma (20 s, seed 1; over 20 seeds before 20 s, the benchmark's startup
    line: 1.4, 1.2 and 0.5 % outside for 0, 90 and 180 degrees). The reset counter goes up once
    when the position jumped at the decision (a heading far from the assumed one), said as such (a
    NOTICE, not a re-initialisation). Before, the filter took the heading through the odometry's
    linearised Jacobian: facing 180 degrees it drove the other way from its prediction, published
    metres off as converged (20 seeds: 33 % outside 3 sigma before 20 s, up to 4.8 m) until
    restarts; facing 90 degrees 20 % outside (0.5 m); facing 0, 4 % (the correction along the
    track is second order in the heading error and always forward)."""
    start, rest = FACING[heading_deg]
    segments = {f"segment{k + 3}": seg for k, seg in enumerate(rest)}
    segments.update({f"segment{k}": None for k in range(3 + len(rest), 16)})
    scenario = scenario_with(tmp_path, "marvelmind", {"start": start, "duration_s": 20, **segments})
    marvelmind = SITE.parent / "marvelmind.ini"
    scenario.write_text(scenario.read_text().replace(f"site = {SITE}", f"site = {marvelmind}"))
    log, truth_path = run_sim(tmp_path, str(scenario), 20, seed=1)
    p, est, _ = replay(bridge_bin, log, tmp_path, site=marvelmind)
    truth = np.genfromtxt(truth_path, delimiter=",", names=True)
    t_sim, err = errors(est, truth)
    moving = t_sim > 5.05
    decided = t_sim[moving & (est["quality"] >= 0)][0]
    assert 5.05 < decided < 7.0, decided
    assert np.all(est["quality"][moving & (t_sim < decided)] < 0)
    ok = (t_sim > 2.0) & (est["quality"] >= 0)
    dx = est["x_m"] - np.interp(est["t_us"], truth["t_us"], truth["x_m"])
    dy = est["y_m"] - np.interp(est["t_us"], truth["t_us"], truth["y_m"])
    a, b, c = est["var_x_m2"], est["cov_xy_m2"], est["var_y_m2"]
    mahal2 = (c * dx * dx - 2 * b * dx * dy + a * dy * dy) / (a * c - b * b)
    assert np.max(err[ok]) < 0.1, float(np.max(err[ok]))
    after = ok & (t_sim >= decided) & (t_sim < decided + 3.0)  # the decision's doing
    assert np.mean(mahal2[after] <= 9) >= 0.97, float(np.mean(mahal2[after] <= 9))
    th_true = np.interp(est["t_us"], truth["t_us"], np.unwrap(truth["theta_rad"]))
    err_th = np.abs(np.angle(np.exp(1j * (est["theta_rad"] - th_true))))
    assert np.max(err_th[t_sim > decided + 2.0]) < 0.15
    assert est["reset_counter"][-1] == (0 if heading_deg == 0 else 1)
    said = [w for w in p.stderr.splitlines() if "heading from the track: pose re-set (reset 1)" in w]
    assert len(said) == (0 if heading_deg == 0 else 1), p.stderr
    assert "re-initialised" not in p.stderr and "restarted" not in p.stderr
