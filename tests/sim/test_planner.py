"""The site planner (beaconloc-sim map) against closed forms on simple geometries."""
from __future__ import annotations

import math
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from beaconloc_sim import cli, crb, planner
from beaconloc_sim.resources import builtin_site_path
from beaconloc_sim.site import load_site

from conftest import SITE_TEXT

HERE = Path(__file__).parent
VANDER = HERE / "vander-table.ini"
BIN = Path(sys.executable).with_name("beaconloc-sim")
SIGMA_RAD = math.radians(1.0)
LINE = re.compile(r"^map site=(\S+) kind=(tdoa|bearing|range|both) step_m=([0-9.e+-]+) "
                  r"drms_median_mm=([0-9.]+) drms_p90_mm=([0-9.]+) drms_worst_mm=([0-9.]+) "
                  r"(heading_median_deg=[0-9.]+ heading_p90_deg=[0-9.]+ "
                  r"heading_worst_deg=[0-9.]+ )?"
                  r"below5cm_pct=([0-9.]+) degenerate_pct=([0-9.]+)$")


def triangle(r_m: float, centre=(0.0, 0.0), first_deg: float = 90.0) -> np.ndarray:
    """Three beacons at distance r from centre, 120 degrees apart, (3, 2)."""
    a = np.radians(first_deg + np.array([0.0, 120.0, 240.0]))
    return np.stack([centre[0] + r_m * np.cos(a), centre[1] + r_m * np.sin(a)], axis=1)


@pytest.mark.parametrize("r_m, sigma_rad", [(1.0, SIGMA_RAD), (2.5, 0.004), (0.3, 0.05)])
def test_bearing_centre_of_equilateral_triangle(r_m, sigma_rad):
    # Each bearing's Jacobian row is (g_j, -1), g_j = (sin a_j, -cos a_j) / r (a_j: direction
    # of beacon j): information 1/(r^2 sigma^2) across its line of sight. At the centre
    # sum_j g_j = 0, so position and heading decouple: F_pp = (1/(r^2 sigma^2)) sum u u^T
    # = 3/(2 r^2 sigma^2) I, F_thth = 3/sigma^2. Hence C_xx = C_yy = 2 r^2 sigma^2 / 3,
    # drms = 2 r sigma / sqrt(3), heading sigma = sigma / sqrt(3).
    for first_deg in (90.0, 17.0):
        F = planner.bearing_fisher(0.0, 0.0, 0.3, triangle(r_m, first_deg=first_deg), (0, 0),
                                   sigma_rad)
        drms, heading, degenerate = planner.position_bound(F)
        assert not degenerate
        assert drms == pytest.approx(2 * r_m * sigma_rad / math.sqrt(3), rel=1e-9)
        assert heading == pytest.approx(sigma_rad / math.sqrt(3), rel=1e-9)
        C = np.linalg.inv(F)
        assert C[0, 0] == pytest.approx(2 * r_m ** 2 * sigma_rad ** 2 / 3, rel=1e-9)
        assert C[0, 1] == pytest.approx(0.0, abs=1e-12 * C[0, 0])


@pytest.mark.parametrize("theta_rad", [0.0, 0.7, -2.0])
def test_bearing_sensor_offset_adds_the_heading_lever_arm(theta_rad):
    # Sensor at the triangle's centre, robot centre behind it: p = s - R(theta) o, so
    # C_p = C_s + (R'(theta) o)(R'(theta) o)^T var(theta) with var(theta) = sigma^2 / 3 and
    # |R' o| = |o|: drms^2 = (4 r^2 + |o|^2) sigma^2 / 3 whatever the heading.
    r_m, offset = 1.2, np.array([0.15, -0.05])
    c, s = math.cos(theta_rad), math.sin(theta_rad)
    x, y = -(c * offset[0] - s * offset[1]), -(s * offset[0] + c * offset[1])
    F = planner.bearing_fisher(x, y, theta_rad, triangle(r_m), offset, SIGMA_RAD)
    drms, heading, degenerate = planner.position_bound(F)
    assert not degenerate
    assert drms ** 2 == pytest.approx((4 * r_m ** 2 + offset @ offset) * SIGMA_RAD ** 2 / 3,
                                      rel=1e-9)
    assert heading == pytest.approx(SIGMA_RAD / math.sqrt(3), rel=1e-9)


def test_bearing_on_the_circle_through_the_beacons_is_degenerate():
    # Vander Fig. 4: robot and beacons concyclic -> every bearing difference is the same along
    # the circle (inscribed angles), so the position is unobservable along it: F singular.
    beacons = triangle(1.5, centre=(2.0, 1.0))
    for angle_deg in (30.0, 150.0, 200.0, 271.0):
        a = math.radians(angle_deg)
        x, y = 2.0 + 1.5 * math.cos(a), 1.0 + 1.5 * math.sin(a)
        drms, heading, degenerate = planner.position_bound(
            planner.bearing_fisher(x, y, 0.0, beacons, (0, 0), SIGMA_RAD))
        assert degenerate and math.isnan(drms) and math.isnan(heading)
        # 1 cm inside the circle is regular, its drms large but finite and capped only by 1 m
        xi, yi = 2.0 + 1.49 * math.cos(a), 1.0 + 1.49 * math.sin(a)
        F_in = planner.bearing_fisher(xi, yi, 0.0, beacons, (0, 0), SIGMA_RAD)
        d_in, _, deg_in = planner.position_bound(F_in, cap_m=np.inf)
        assert not deg_in and 0.2 < d_in < 10.0


def test_bearing_two_beacons_and_beacon_cells_are_degenerate():
    drms, _, deg = planner.position_bound(
        planner.bearing_fisher(np.array([0.5, 1.0]), np.array([0.5, 0.2]), 0.0,
                               triangle(1.0)[:2], (0, 0), SIGMA_RAD))
    assert deg.all() and np.isnan(drms).all()
    # a cell centre on a beacon: r = 0, non-finite information, marked, no exception
    b = triangle(1.0)
    drms, _, deg = planner.position_bound(
        planner.bearing_fisher(b[0, 0], b[0, 1], 0.0, b, (0, 0), SIGMA_RAD))
    assert deg and math.isnan(drms)


def test_static_arrival_jacobian_is_eq21_at_rest():
    # the analytic columns equal crb.arrival_jacobian's (central differences of eq. 21)
    beacons = np.array([[0.05, 3.0, 1.0], [6.0, 11.95, 1.8], [11.0, 0.5, 0.2]])
    for x, y in ((2.0, 3.5), (7.3, 9.1)):
        J = crb.static_arrival_jacobian(x, y, beacons, 0.6, 343.0)
        for i, b in enumerate(beacons):
            state = np.array([x, y, 0.4, 0.0, 0.0, 343.0, 0.15, 0.0])
            num = crb.arrival_jacobian(state, b, np.array([0.0]), 0.0, 0.6)[0]
            np.testing.assert_allclose(J[i], num[[crb.IX, crb.IY, crb.IT0]], rtol=1e-6)


@pytest.mark.parametrize("dz_m", [0.0, 0.8])
def test_tdoa_centre_of_square(dz_m):
    # 4 beacons at the corners (+-a, +-a, z), receiver at the centre at height z + dz. Rows:
    # (rho/d u_j / s, 1), u_j the horizontal unit vectors at 45 + 90 j deg, rho = a sqrt(2),
    # d = sqrt(rho^2 + dz^2). sum u_j = 0: (x, y) and t0 decouple; F_pp = (rho/d)^2 / (s sigma)^2
    # sum u u^T = 2 (rho/d)^2 / (s sigma)^2 I, so C_xx = C_yy = (s sigma d/rho)^2 / 2 and
    # drms = s sigma d / rho; F_t0t0 = 4 / sigma^2 (t0's sigma = sigma / 2).
    a_m, s_mps, sigma_s, z_m = 2.0, 343.0, 2e-4, 1.0
    beacons = np.array([[a_m, a_m, z_m], [-a_m, a_m, z_m], [-a_m, -a_m, z_m], [a_m, -a_m, z_m]])
    rho, d = a_m * math.sqrt(2), math.hypot(a_m * math.sqrt(2), dz_m)
    F = planner.tdoa_fisher(0.0, 0.0, beacons, z_m + dz_m, s_mps, sigma_s)
    drms, t0_sigma, degenerate = planner.position_bound(F)
    assert not degenerate
    assert drms == pytest.approx(s_mps * sigma_s * d / rho, rel=1e-9)
    assert t0_sigma == pytest.approx(sigma_s / 2, rel=1e-9)


def test_tdoa_three_collinear_beacons_are_degenerate():
    beacons = np.array([[0.0, 0.0, 1.0], [2.0, 0.0, 1.0], [4.0, 0.0, 1.0]])
    _, _, deg = planner.position_bound(planner.tdoa_fisher(
        np.array([1.0, 3.0]), np.array([0.0, 0.0]), beacons, 1.0, 343.0, 2e-4))
    assert deg.all()


def test_drms_scales_linearly_with_sigma():
    site = load_site(VANDER)
    one = planner.kind_map(site, "bearing", 0.05, cap_m=np.inf)
    two = planner.kind_map(site, "bearing", 0.05, cap_m=np.inf, sigma_scale=2.0)
    ok = ~one.degenerate & ~two.degenerate
    assert ok.mean() > 0.9
    np.testing.assert_allclose(two.drms_m[ok], 2 * one.drms_m[ok], rtol=1e-9)
    np.testing.assert_allclose(two.heading_sigma_rad[ok], 2 * one.heading_sigma_rad[ok], rtol=1e-9)
    tdoa = load_site(builtin_site_path())
    one, three = (planner.kind_map(tdoa, "tdoa", 0.5, sigma_scale=k) for k in (1.0, 3.0))
    np.testing.assert_allclose(three.drms_m, 3 * one.drms_m, rtol=1e-9)


def test_vander_fig5_right_half_better_than_left():
    # Vander Fig. 5 (sigma_phi = 1 deg): the good region is on the right (the beacons B1, B3 side)
    m = planner.kind_map(load_site(VANDER), "bearing", 0.02)
    h = m.halves(1.5)
    assert h["right_below5cm_pct"] > 50 > 10 > h["left_below5cm_pct"]
    assert h["right_median_mm"] < 50 < h["left_median_mm"]
    assert h["right_degenerate_pct"] == 0 < h["left_degenerate_pct"]


def mixed_site_text() -> str:
    """kleeman-lab with three bearing beacons added (a site with both kinds)."""
    return SITE_TEXT.replace("[bridge]", "[bearing_beacons]\ncount = 3\n\n"
                             "[bearing_beacon1]\nx_m = 0.0\ny_m = 0.0\n\n"
                             "[bearing_beacon2]\nx_m = 12.0\ny_m = 6.0\n\n"
                             "[bearing_beacon3]\nx_m = 0.0\ny_m = 12.0\n\n"
                             "[bearing_sensor]\nsigma_deg = 0.5\n\n[bridge]")


def test_both_kinds_fused_are_better_than_each(tmp_path):
    path = tmp_path / "mixed.ini"
    path.write_text(mixed_site_text())
    site = load_site(path)
    assert planner.kinds_of(site) == ["tdoa", "bearing", "both"]
    maps = {k: planner.kind_map(site, k, 0.25, cap_m=np.inf) for k in planner.kinds_of(site)}
    ok = ~maps["both"].degenerate & ~maps["tdoa"].degenerate & ~maps["bearing"].degenerate
    assert ok.mean() > 0.9
    best = np.fmin(maps["tdoa"].drms_m, maps["bearing"].drms_m)[ok]
    assert np.all(maps["both"].drms_m[ok] <= best * (1 + 1e-12))
    assert np.mean(maps["both"].drms_m[ok] < 0.95 * best) > 0.5


def test_cli_writes_png_and_prints_the_documented_lines(tmp_path):
    site = tmp_path / "mixed.ini"
    site.write_text(mixed_site_text())
    out = tmp_path / "map.png"
    proc = subprocess.run([str(BIN), "map", str(site), "--out", str(out), "--step", "0.2"],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and out.stat().st_size > 10_000
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("map ")]
    assert [LINE.match(ln).group(2) for ln in lines] == ["tdoa", "bearing", "both"]
    assert proc.stdout.splitlines()[-1] == lines[-1]
    last = LINE.match(lines[-1])
    assert last.group(1) == "kleeman-lab" and float(last.group(3)) == 0.2
    assert last.group(7) is not None          # both: heading figures
    assert LINE.match(lines[0]).group(7) is None


def test_cli_halves_and_vander_numbers(capsys):
    assert cli.main(["map", str(VANDER), "--kind", "bearing", "--halves", "--step", "0.05"]) == 0
    lines = capsys.readouterr().out.splitlines()
    halves = dict(kv.split("=") for kv in lines[-2].split()[1:])
    assert halves["kind"] == "bearing" and float(halves["split_x_m"]) == 1.5
    m = LINE.match(lines[-1])
    assert m and m.group(1) == "vander-table"
    assert float(halves["right_below5cm_pct"]) > float(halves["left_below5cm_pct"])
    assert float(halves["left_worst_mm"]) == pytest.approx(float(m.group(6)), abs=0.05)


def test_cli_exit_2_without_the_requested_kind(tmp_path, capsys):
    out = tmp_path / "x.png"
    assert cli.main(["map", "kleeman-lab", "--kind", "bearing"]) == 2
    assert "no bearing beacons" in capsys.readouterr().err
    assert cli.main(["map", str(VANDER), "--kind", "tdoa"]) == 2
    assert "no ultrasonic beacons" in capsys.readouterr().err
    assert cli.main(["map", str(VANDER), "--kind", "both", "--out", str(out)]) == 2
    assert not (tmp_path / "x.png").exists()


def test_bearing_bound_depends_on_heading_only_through_the_offset(tmp_path):
    beacons = np.array([[3.0, 2.1], [0.0, 1.05], [3.0, 0.0]])
    x, y = np.array([0.7, 2.2, 1.4]), np.array([0.3, 1.6, 1.0])
    bound = [planner.position_bound(planner.bearing_fisher(x, y, np.full(3, th), beacons,
                                                           offset, SIGMA_RAD))[0]
             for offset in ((0, 0), (0.1, 0.05)) for th in (0.0, 1.3)]
    np.testing.assert_allclose(bound[0], bound[1], rtol=1e-12)
    assert np.all(np.abs(bound[2] / bound[3] - 1) > 1e-4)
    # the site planner takes the worst of 8 headings when the sensor is offset, and says so
    path = tmp_path / "offset.ini"
    path.write_text(VANDER.read_text().replace("offset_x_m = 0.0", "offset_x_m = 0.1"))
    site = load_site(path)
    m = planner.kind_map(site, "bearing", 0.1)
    assert len(m.headings_rad) == 8
    per_heading = [planner.position_bound(planner.bearing_fisher(
        *np.meshgrid(m.x_m, m.y_m), np.full((len(m.y_m), len(m.x_m)), th),
        site.bearing_beacons_m, site.bearing_offset_m, SIGMA_RAD))[0] for th in m.headings_rad]
    ok = ~m.degenerate
    np.testing.assert_array_equal(m.drms_m[ok], np.max(per_heading, axis=0)[ok])


def square(a_m: float, centre=(0.0, 0.0), z_m: float = 0.0, first_deg: float = 0.0) -> np.ndarray:
    """Four beacons at horizontal distance a from centre, 90 degrees apart, at height z, (4, 3)."""
    ang = np.radians(first_deg + np.array([0.0, 90.0, 180.0, 270.0]))
    return np.stack([centre[0] + a_m * np.cos(ang), centre[1] + a_m * np.sin(ang),
                     np.full(4, z_m)], axis=1)


@pytest.mark.parametrize("a_m, dz_m, sigma_m, per_m", [(2.0, 0.0, 0.008, 0.005),
                                                       (4.1, 2.2, 0.008, 0.005),
                                                       (0.5, 0.0, 0.02, 0.0)])
def test_range_centre_of_square(a_m, dz_m, sigma_m, per_m):
    # Each range's Jacobian row (x, y) is the horizontal part of the unit vector from the
    # beacon, u_j = (a / d) e_j, d = sqrt(a^2 + dz^2), with sigma = sigma_m + per_m d. At the
    # centre the e_j are 90 degrees apart, sum e_j e_j^T = 2 I, so F = 2 (a/d)^2 I / sigma^2,
    # C = sigma^2 d^2 / (2 a^2) I and drms = sqrt(C_xx + C_yy) = sigma d / a (= sigma when
    # the beacons are at the receiver's height).
    d = math.hypot(a_m, dz_m)
    sigma = sigma_m + per_m * d
    for first_deg in (0.0, 45.0, 10.0):
        F = planner.range_fisher(0.0, 0.0, square(a_m, z_m=0.3 + dz_m, first_deg=first_deg),
                                 0.3, sigma_m, per_m)
        drms, _, degenerate = planner.position_bound(F)
        assert not degenerate
        assert drms == pytest.approx(sigma * d / a_m, rel=1e-12)
        np.testing.assert_allclose(np.linalg.inv(F),
                                   np.eye(2) * sigma ** 2 * d ** 2 / (2 * a_m ** 2),
                                   rtol=1e-12, atol=1e-18)


def test_range_beyond_max_range_adds_nothing_and_two_collinear_are_degenerate():
    b = square(2.0, z_m=0.3)
    # only beacons 1 and 3 (on the x axis) within 1.5 m of (0.6, 0): x known, y not
    F = planner.range_fisher(0.6, 0.0, b, 0.3, 0.01, 0.0, max_range_m=2.0)
    assert F[1, 1] == pytest.approx(0.0, abs=1e-20)
    assert planner.position_bound(F)[2]
    # all four in range: regular
    assert not planner.position_bound(planner.range_fisher(0.6, 0.0, b, 0.3, 0.01, 0.0))[2]


def range_site_text(extra: str = "") -> str:
    """kleeman-lab with four range beacons at the receiver's height (1.0 m) around (6, 6)."""
    return SITE_TEXT.replace("[bridge]", "[range_beacons]\ncount = 4\n\n"
                             "[range_beacon1]\nx_m = 9.0\ny_m = 6.0\nz_m = 1.0\n\n"
                             "[range_beacon2]\nx_m = 6.0\ny_m = 9.0\nz_m = 1.0\n\n"
                             "[range_beacon3]\nx_m = 3.0\ny_m = 6.0\nz_m = 1.0\n\n"
                             "[range_beacon4]\nx_m = 6.0\ny_m = 3.0\nz_m = 1.0\n\n"
                             "[range_sensor]\nheight_m = 1.0\nsigma_m = 0.01\n"
                             "sigma_per_m = 0.005\nmax_range_m = 30\n\n" + extra + "[bridge]")


def test_range_map_closed_form_at_the_centre_and_mixed_site_fuses_ranges(tmp_path):
    path = tmp_path / "ranges.ini"
    path.write_text(range_site_text())
    site = load_site(path)
    assert planner.kinds_of(site) == ["tdoa", "range", "both"]
    # 13 cells a side: the middle one's centre is (6, 6), the beacons' centre
    maps = {k: planner.kind_map(site, k, 12.0 / 13, cap_m=np.inf) for k in planner.kinds_of(site)}
    m = maps["range"]
    assert m.heading_sigma_rad is None and maps["both"].heading_sigma_rad is None
    i, j = int(np.argmin(np.abs(m.y_m - 6.0))), int(np.argmin(np.abs(m.x_m - 6.0)))
    assert m.x_m[j] == pytest.approx(6.0) and m.y_m[i] == pytest.approx(6.0)
    # the closed form: drms = sigma = 0.01 + 0.005 * 3 m (test_range_centre_of_square)
    assert m.drms_m[i, j] == pytest.approx(0.025, rel=1e-9)
    ok = ~maps["both"].degenerate & ~maps["tdoa"].degenerate & ~m.degenerate
    assert ok.mean() > 0.9
    best = np.fmin(maps["tdoa"].drms_m, m.drms_m)[ok]
    assert np.all(maps["both"].drms_m[ok] <= best * (1 + 1e-9))
    assert np.mean(maps["both"].drms_m[ok] < 0.99 * best) > 0.5


def test_cli_map_marvelmind_prints_the_range_line(capsys):
    assert cli.main(["map", "marvelmind", "--step", "0.1"]) == 0
    lines = capsys.readouterr().out.splitlines()
    m = LINE.match(lines[-1])
    assert m and m.group(1) == "marvelmind" and m.group(2) == "range"
    assert m.group(7) is None                  # no heading figures without bearings
    # every cell hears at least three beacons at 8 m: none degenerate; 2.5-6 cm everywhere
    assert float(m.group(9)) == 0.0
    assert 25 < float(m.group(4)) < float(m.group(6)) < 65
    assert cli.main(["map", "kleeman-lab", "--kind", "range"]) == 2
    assert "no range beacons" in capsys.readouterr().err
