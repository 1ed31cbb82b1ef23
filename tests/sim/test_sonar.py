"""The sonar ring's physics and node (issue 12): perpendicular distance inside the cone, no
echo beyond the critical incidence, corner double bounce as a phantom, blanking, max range,
flags, crosstalk, the node's speed of sound, the burst schedule, frames through cantools and
the sonar's posterior bound."""
from __future__ import annotations

import math
import re

import cantools
import numpy as np
import pytest

from beaconloc_sim import simulate
from beaconloc_sim.nodes.sonar_ring import SonarRing
from beaconloc_sim.physics import sonar as so
from beaconloc_sim.resources import builtin_site_path, dbc_path
from beaconloc_sim.scenario import load_scenario

ID_SONAR = SonarRing.frame_spec().frame_id

BEAM = so.Beam.of(math.radians(30), math.radians(5), 1.0)   # 30 deg full width, 5 deg rough
WALL = np.array([[5.0, 0.0, 5.0, 4.0]])                     # the line x = 5, 4 m long
ROOM = np.array([[0, 0, 6, 0], [6, 0, 6, 4], [6, 4, 0, 4], [0, 4, 0, 0]], float)
HOPPENOT = builtin_site_path("hoppenot-room").read_text()


# ---- the beam ----------------------------------------------------------------------------

def test_piston_half_power_at_the_beam_edge():
    """D(beta) = 1/sqrt(2) one way at half the full width; 1 on the axis; J1 is J1."""
    ka = so.piston_ka(math.radians(30))
    assert so.directivity(0.0, ka) == 1.0
    assert so.directivity(math.radians(15), ka) == pytest.approx(1 / math.sqrt(2), abs=1e-12)
    # tabulated J1 (Abramowitz & Stegun table 9.1): J1(1) = 0.4400505857, J1(3.8317) ~ 0
    assert so.bessel_j1(1.0) == pytest.approx(0.4400505857, abs=1e-10)
    assert abs(so.bessel_j1(3.8317059702)) < 1e-9
    # a narrower beam is a larger piston
    assert so.piston_ka(math.radians(20)) > ka


# ---- first-order echoes: perpendicular distance, critical incidence ------------------------

@pytest.mark.parametrize("axis_deg", [0.0, 5.0, 10.0, -14.0])
def test_perpendicular_distance_when_the_normal_is_inside_the_cone(axis_deg):
    """The wall's normal through the sonar is within 15 deg of the axis: the echo is the
    perpendicular distance 4 m, not the along-axis 4 / cos(axis)."""
    e = so.echoes([1.0, 2.0], math.radians(axis_deg), WALL, BEAM)
    assert e.kind.tolist() == [so.KIND_SPECULAR]
    assert e.range_m[0] == pytest.approx(4.0, abs=1e-12)
    assert e.incidence_rad[0] == 0.0
    # amplitude: the two-way directivity D(psi)^2
    assert e.amplitude[0] == pytest.approx(so.directivity(math.radians(axis_deg), BEAM.ka) ** 2)


def test_oblique_echo_between_the_cone_and_the_critical_incidence():
    """Normal 18 deg off the axis: the nearest wall point inside the cone is on the cone's
    edge, hit at 3 deg incidence (< 5): an echo at 4 / cos(3 deg), weaker than a specular."""
    e = so.echoes([1.0, 2.0], math.radians(18), WALL, BEAM)
    assert e.kind.tolist() == [so.KIND_OBLIQUE]
    assert e.range_m[0] == pytest.approx(4.0 / math.cos(math.radians(3)), rel=1e-9)
    assert math.degrees(e.incidence_rad[0]) == pytest.approx(3.0, abs=1e-9)
    assert e.amplitude[0] < 0.5 * so.directivity(math.radians(15), BEAM.ka) ** 2


@pytest.mark.parametrize("axis_deg", [20.5, 30.0, 45.0, 80.0])
def test_no_echo_beyond_the_critical_incidence(axis_deg):
    """Normal more than half the beam + 5 deg off the axis: the sound is reflected away."""
    assert len(so.echoes([1.0, 2.0], math.radians(axis_deg), WALL, BEAM).range_m) == 0


def test_wall_end_and_occlusion():
    """A segment whose perpendicular foot is off its end echoes only from its end within the
    critical incidence; a segment in front hides the one behind."""
    short = np.array([[5.0, 2.5, 5.0, 4.0]])      # foot (5, 2) is not on it
    assert len(so.echoes([1.0, 2.0], 0.0, short, BEAM).range_m) == 0   # end at 7 deg
    screen = np.array([[3.0, 1.0, 3.0, 3.0]])
    e = so.echoes([1.0, 2.0], 0.0, np.vstack([WALL, screen]), BEAM)
    assert e.first.tolist() == [1] and e.range_m[0] == pytest.approx(2.0)


# ---- double bounces ------------------------------------------------------------------------

def test_corner_double_bounce_is_a_phantom():
    """Aimed 10 deg beside a corner of the room, no wall is within the critical incidence,
    but the sound comes back from the corner by two reflections: range = distance to the
    apex, and the impact point along the axis at that range lies outside the room."""
    p, axis = np.array([4.0, 2.0]), math.radians(55)
    first = so.first_order(p, axis, ROOM, BEAM)
    assert len(first.range_m) == 0
    e = so.echoes(p, axis, ROOM, BEAM)
    assert set(e.kind.tolist()) == {so.KIND_DOUBLE}
    assert {frozenset(w) for w in zip(e.first.tolist(), e.second.tolist())} == {frozenset({1, 2})}
    r = math.hypot(6 - 4, 4 - 2)
    np.testing.assert_allclose(e.range_m, r, atol=1e-9)
    impact = p + r * np.array([math.cos(axis), math.sin(axis)])
    assert impact[1] > 4.0                     # beyond the wall y = 4: a phantom
    assert so.echoes(p, axis, ROOM, BEAM, double=False).range_m.size == 0


def test_double_bounce_between_two_walls_off_a_corner():
    """sonar -> wall A -> wall B -> sonar where A and B are not a corner: the path length
    from the image of the image (Allen & Berkley), checked against the unfolded legs."""
    walls = np.array([[0.0, 0.0, 10.0, 0.0], [8.0, -1.0, 8.0, 6.0]])
    e = so.second_order(np.array([2.0, 1.0]), math.radians(-5), walls, BEAM)
    assert len(e.range_m) >= 1
    # the unfolded path: images of (2, 1) in y = 0 then in x = 8: (14, -1); half its distance
    assert e.range_m.min() == pytest.approx(math.hypot(14 - 2, -1 - 1) / 2, rel=1e-12)


# ---- crosstalk -----------------------------------------------------------------------------

def test_crosstalk_path_between_two_parallel_sonars():
    """Sonar A at (1, 1.9) and B at (1, 2.1) both facing the wall x = 5: A's ping reaches B
    by one reflection at the midpoint, path sqrt(8^2 + 0.2^2)."""
    x = so.crosstalk_paths([1.0, 1.9], 0.0, [1.0, 2.1], 0.0, WALL, BEAM)
    assert x.kind.tolist() == [so.KIND_CROSSTALK]
    assert 2 * x.range_m[0] == pytest.approx(math.hypot(8.0, 0.2), rel=1e-12)


# ---- the node, through a simulated run ---------------------------------------------------

def _site_text(**sonar_ring) -> str:
    text = HOPPENOT
    for key, value in sonar_ring.items():
        text, n = re.subn(rf"(\[sonar_ring\][^\[]*?^{key}\s*=)[^\n]*", rf"\g<1> {value}", text,
                          flags=re.MULTILINE | re.DOTALL)
        assert n == 1, key
    return text


def _run(tmp_path, scenario_body: str, site_text: str | None = None, name: str = "t"):
    (tmp_path / "site.ini").write_text(site_text or HOPPENOT)
    path = tmp_path / f"{name}.scenario.ini"
    path.write_text("[scenario]\nsite = site.ini\nseed = 3\n" + scenario_body)
    return simulate.run(load_scenario(str(path)))


PARKED = "duration_s = {d}\n[path]\nstart = {x}, {y}, {deg}\nsegment1 = wait {d}\n"


def test_node_reports_perpendicular_range_with_its_noise_and_speed_of_sound(tmp_path):
    """Parked at (2, 3.5) facing +x, sonar 1 (axis 0, mount 0.2 m forward) sees the wall
    x = 6 (above the door) at 3.8 m. At 0 degC the sound travels at 331.5 m/s but the node converts with
    343 m/s: the ranges read 3.8 * 343 / c(0 degC); their spread is sigma(3.8 m) = 3.8 cm."""
    res = _run(tmp_path, PARKED.format(d=100, x=2, y=3.5, deg=0) +
               "[environment]\ntemperature_c = 0\n")
    s = res.sonar
    mine = (s.sensor == 0) & (s.flags == 0)
    assert mine.sum() == 200                             # one per burst, every 0.5 s
    assert np.all(s.kind[mine] == so.KIND_SPECULAR) and np.all(s.wall[mine] == 2)
    c0 = s.sos_mps[mine][0]
    assert c0 == pytest.approx(331.5, abs=0.2)
    expect = 3.8 * 343.0 / c0
    np.testing.assert_allclose(s.true_m[mine], expect, rtol=1e-12)
    r = s.range_mm[mine] / 1000.0
    assert r.mean() == pytest.approx(expect, abs=3 * 0.038 / math.sqrt(200))
    assert r.std(ddof=1) == pytest.approx(0.01 * expect, rel=0.2)


def test_burst_schedule_flags_and_frames_round_trip(tmp_path):
    """Every sonar sends one frame per burst at NodeTime n P + i F (P = 0.5 s, F = 0.06 s);
    the back sonar parked 0.1 m from a wall is blanked (NO_ECHO: the blanking hides its only
    echo); through the door with nothing beyond, NO_ECHO too; every frame decodes with
    cantools to the signals the node built."""
    res = _run(tmp_path, PARKED.format(d=10, x=5.3, y=2.0, deg=0) + "[obstacles]\n")
    frames = res.frames
    sonar = frames.arb_id == ID_SONAR
    assert sonar.sum() == 20 * 8
    db = cantools.database.load_file(str(dbc_path()))
    sig = [frames.signals[i] for i in np.flatnonzero(sonar)]
    for i, s in zip(np.flatnonzero(sonar), sig):
        assert db.decode_message(int(frames.arb_id[i]), frames.data[i], decode_choices=False) == s
    t = np.array([s["NodeTime"] for s in sig], dtype=np.int64)
    sensor = np.array([s["Sensor"] for s in sig])
    offset = res.scenario.sonar.offset_us
    assert np.all((t - sensor * 60_000) % 500_000 == 0)   # the node's counts n P + i F
    assert np.all(np.diff([s["Counter"] for s in sig]) % 16 == 1)
    forward = [s for s in sig if s["Sensor"] == 0]
    assert all(s["Flags"] == 1 and s["Range"] == 0 and s["Amplitude"] == 0 for s in forward)
    assert offset % 500_000 != 0               # the schedule is the node clock's, not t = 0


def test_blanking_hides_a_close_wall(tmp_path):
    """The back sonar (mount 0.2 m behind, axis 180 deg) of a robot at x = 0.35 facing +x is
    0.15 m from the wall x = 0: with min_range_m 0.20 it hears nothing of it (NO_ECHO); with
    0.10 it reads 0.15 m."""
    body = PARKED.format(d=5, x=0.35, y=2.0, deg=0)
    blanked = _run(tmp_path, body, _site_text(min_range_m=0.20)).sonar
    heard = _run(tmp_path, body, _site_text(min_range_m=0.10)).sonar
    back_b, back_h = blanked.sensor == 4, heard.sensor == 4
    assert np.all(blanked.flags[back_b] == 1)
    assert np.all(heard.flags[back_h] == 0)
    np.testing.assert_allclose(heard.true_m[back_h], 0.15 * 343.0 / heard.sos_mps[back_h])


def test_max_range_flag(tmp_path):
    """With max_range_m 3 and the wall 3.8 m ahead, the forward sonar's echo still arrives
    inside its 60 ms listening window: MAX_RANGE, Range 0, the echo's amplitude kept."""
    res = _run(tmp_path, PARKED.format(d=5, x=2, y=3.5, deg=0), _site_text(max_range_m=3.0))
    fwd = [s for fid, s in zip(res.frames.arb_id, res.frames.signals)
           if fid == ID_SONAR and s["Sensor"] == 0]
    assert fwd and all(s["Flags"] == 2 and s["Range"] == 0 and s["Amplitude"] == 255
                       for s in fwd)


def test_crosstalk_between_sonars_fired_close_together(tmp_path):
    """Two parallel sonars 0.2 m apart facing a wall 2.8 m away, fired 5 ms apart: the second
    hears the first's echo before its own, at (L - c 5 ms) / 2 = 1.94 m; with crosstalk off,
    or fired 60 ms apart, it reads its own 2.8 m."""
    site = re.sub(r"\[sonar3\].*?(?=\[map\])", "", _site_text(count=2),
                  flags=re.DOTALL)
    site = site.replace("[sonar2]\nx_m = 0.1732\ny_m = 0.10\nangle_deg = 30",
                        "[sonar2]\nx_m = 0.20\ny_m = 0.20\nangle_deg = 0")
    assert "[sonar3]" not in site and "angle_deg = 30" not in site
    body = PARKED.format(d=5, x=3.0, y=3.3, deg=0)   # facing the wall above the door
    near = _run(tmp_path, body + "[sonar]\nfire_interval_s = 0.005\n", site, "near").sonar
    off = _run(tmp_path, body + "[sonar]\nfire_interval_s = 0.005\ncrosstalk = 0\n", site,
               "off").sonar
    far = _run(tmp_path, body, site, "far").sonar
    second = near.sensor == 1
    assert np.all(near.kind[second] == so.KIND_CROSSTALK)
    c = near.sos_mps[second][0]
    path = math.hypot(2 * 2.8, 0.2)
    # 5 ms of the node's clock, 25 ppm fast: the true gap between the two pings
    gap = near.t_s[second][0] - near.t_s[near.sensor == 0][0]
    assert gap == pytest.approx(0.005 / (1 + 25e-6), abs=1e-9)
    expect = (path - c * gap) / 2 * 343.0 / c
    np.testing.assert_allclose(near.true_m[second], expect, rtol=1e-6)
    for quiet in (off, far):
        assert np.all(quiet.kind[quiet.sensor == 1] == so.KIND_SPECULAR)
        np.testing.assert_allclose(quiet.true_m[quiet.sensor == 1], 2.8 * 343.0 / c, rtol=1e-9)


def test_unknown_obstacle_is_heard_and_not_in_the_map(tmp_path):
    """hoppenot-obstacle: the cabinet (an [obstacles] segment) answers some pings; they are not
    map echoes and the bound leaves them out."""
    res = simulate.run(load_scenario("hoppenot-obstacle"))
    s = res.sonar
    n_map = len(res.scenario.site.walls_m)
    cabinet = s.wall >= n_map + 3           # segments 4.. of [obstacles]: the cabinet
    assert cabinet.sum() > 5
    assert not np.any(s.in_map[cabinet]) and not np.any(s.informative[cabinet])


# ---- the bound -----------------------------------------------------------------------------

def test_perpendicular_rows_are_the_range_gradient():
    mount = (0.2, 0.1, math.radians(30), 1)
    wall = (6.0, 0.0, 6.0, 4.0)
    r, g = so.perpendicular_rows(2.0, 1.5, 0.3, mount, wall)
    h = 1e-6
    for i in range(3):
        x = [2.0, 1.5, 0.3]
        x[i] += h
        up = so.perpendicular_rows(*x, mount, wall)[0]
        x[i] -= 2 * h
        down = so.perpendicular_rows(*x, mount, wall)[0]
        assert g[i] == pytest.approx((up - down) / (2 * h), abs=1e-7)
    pos, _ = so.sensor_pose(2.0, 1.5, 0.3, mount)
    assert r == pytest.approx(6.0 - pos[0, 0])


def test_bound_of_a_parked_robot_is_sigma_over_sqrt_n(tmp_path):
    """Parked at (2, 3.5) facing +x: sonar 1 reads the wall x = 6 (3.8 m, sigma 3.8 cm) and
    sonars 4 and 6 the walls y = 4.5 and y = 0 at 0.8 m and 3.3 m (sigma 3 and 3.3 cm), every
    0.5 s (sonar 5, looking back, is not used: not in the bound).
    After N bursts the bound on x is about sigma_x / sqrt(N) (the speed of sound known to
    1 mm/s here), on y the two walls' combined information."""
    site = HOPPENOT.replace("sigma_speed_of_sound_mps = 1.0", "sigma_speed_of_sound_mps = 0.001")
    res = _run(tmp_path, PARKED.format(d=20, x=2, y=3.5, deg=0), site)
    s = res.sonar
    info = s.informative
    n_x = int(np.sum(info & (s.sensor == 0) & (s.wall == 2)))
    n_top = int(np.sum(info & (s.sensor == 3) & (s.wall == 3)))
    n_bottom = int(np.sum(info & (s.sensor == 5) & (s.wall == 0)))
    assert n_x == n_top == n_bottom == 40
    assert np.sum(info & (s.sensor == 4)) == 40       # the back sonar hears x = 0, unused
    end = res.truth["t_sim_s"] >= 19.9
    gain = 343.0 / s.sos_mps[0]               # range = r c_node / c
    expect_x = 1.0 / math.sqrt(1.0 + n_x * gain ** 2 / (0.038 ** 2 + 1e-6 / 12))
    assert res.truth["pcrb_x_m"][end][-1] == pytest.approx(expect_x, rel=0.05)
    expect_y = 1.0 / math.sqrt(1.0 + n_top * gain ** 2 / (0.03 ** 2 + 1e-6 / 12)
                               + n_bottom * gain ** 2 / (0.033 ** 2 + 1e-6 / 12))
    assert res.truth["pcrb_y_m"][end][-1] == pytest.approx(expect_y, rel=0.05)


# ---- the accuracy map (beaconloc-sim map) ------------------------------------------------

def _two_sonar_site(tmp_path, walls: list[tuple[float, float, float, float]]):
    from beaconloc_sim.site import load_site
    site = re.sub(r"\[sonar3\].*", "", _site_text(count=2), flags=re.DOTALL)
    site = site.replace("[sonar2]\nx_m = 0.1732\ny_m = 0.10\nangle_deg = 30",
                        "[sonar2]\nx_m = 0.0\ny_m = 0.20\nangle_deg = 90")
    site += f"\n[map]\nwalls = {len(walls)}\n" + "".join(
        f"\n[wall{i}]\nx1_m = {w[0]}\ny1_m = {w[1]}\nx2_m = {w[2]}\ny2_m = {w[3]}\n"
        for i, w in enumerate(walls, start=1))
    (tmp_path / "two.ini").write_text(site)
    return load_site(tmp_path / "two.ini")


def test_sonar_map_is_the_two_walls_information(tmp_path):
    """One burst of a forward and a left sonar at (2, 2), heading 0, in a closed 6 x 4.5 m
    room: x from the wall 3.8 m ahead (sigma 3.8 cm), y from the wall 2.3 m left (3 cm):
    drms = sqrt(0.038^2 + 0.03^2); with the map a corridor (walls y = 0, 4.5 only) x is
    unobserved: degenerate."""
    from beaconloc_sim import planner
    room = [(0, 0, 6, 0), (6, 0, 6, 4.5), (6, 4.5, 0, 4.5), (0, 4.5, 0, 0)]
    site = _two_sonar_site(tmp_path, room)
    F = planner.sonar_fisher(site, np.array([2.0]), np.array([2.0]), 0.0)
    np.testing.assert_allclose(F[0], np.diag([1 / 0.038 ** 2, 1 / 0.03 ** 2]), rtol=1e-9)
    drms, _, degenerate = planner.position_bound(F)
    assert not degenerate[0] and drms[0] == pytest.approx(math.hypot(0.038, 0.03), rel=1e-9)
    corridor = _two_sonar_site(tmp_path, [room[0], room[2]])
    _, _, degenerate = planner.position_bound(
        planner.sonar_fisher(corridor, np.array([2.0]), np.array([2.0]), 0.0))
    assert degenerate[0]


def test_cli_map_draws_the_sonar_accuracy(tmp_path, capsys):
    from beaconloc_sim import cli
    png = tmp_path / "sonar.png"
    assert cli.main(["map", "hoppenot-room", "--kind", "sonar", "--step", "0.1",
                     "--out", str(png)]) == 0
    line = capsys.readouterr().out.strip().splitlines()[-1]
    assert line.startswith("map site=hoppenot-room kind=sonar step_m=0.1 ")
    median = float(re.search(r"drms_median_mm=([0-9.]+)", line).group(1))
    assert 30.0 < median < 70.0          # two or three 3-4 cm ranges per burst
    assert png.stat().st_size > 10_000
    assert cli.main(["map", "kleeman-lab", "--kind", "sonar"]) == 2


def test_draw_walls_draws_the_map_and_the_obstacles():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from beaconloc_sim.plot import draw_walls
    scn = load_scenario("hoppenot-obstacle")
    fig, ax = plt.subplots()
    draw_walls(ax, scn.site, scn.obstacles_m)
    lines = ax.get_lines()
    assert len(lines) == len(scn.site.walls_m) + len(scn.obstacles_m) == 5 + 6
    assert [ln.get_label() for ln in lines].count("map wall") == 1
    np.testing.assert_allclose(lines[1].get_xydata(), [[6.0, 0.0], [6.0, 1.5]])
    plt.close(fig)


def test_rough_walls_echo_off_the_normal():
    """hoppenot-rough (walls that echo up to 30 degrees of incidence, the paper's s. 5.2): the
    same path as hoppenot-room, and the extra readings are oblique echoes of the map's walls,
    heard beyond the smooth walls' 20 degrees (docs/performance.md, the pin-point's heading)."""
    smooth = simulate.run(load_scenario("hoppenot-room")).sonar
    rough_res = simulate.run(load_scenario("hoppenot-rough"))
    rough = rough_res.sonar
    assert rough_res.scenario.sonar.critical_rad == pytest.approx(math.radians(30))
    n_map = len(rough_res.scenario.site.walls_m)
    obl_smooth = int(np.sum((smooth.kind == so.KIND_OBLIQUE) & (smooth.wall < n_map)))
    obl_rough = int(np.sum((rough.kind == so.KIND_OBLIQUE) & (rough.wall < n_map)))
    # the 80 bursts of the path hear the walls off their normal (measured: 155 oblique echoes
    # of map walls against 10 with smooth walls)
    assert obl_rough > obl_smooth + 100
    assert len(rough.kind) == len(smooth.kind)       # the same pings: only the walls differ
