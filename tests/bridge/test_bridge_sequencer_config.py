"""A beacon period too short for the sequencer's windows: the bridge exits 78
naming file, line and key ([beacons] period_s) and the real cause, the
distance that sets the longest flight (the site's hearing range, or without
one the largest beacon distance) and the period it needs (issue 14)."""
import re
import subprocess

from beaconloc_sim.scenario import load_scenario

SCENARIOS = "hw_sim/beaconloc_sim/data/scenarios"


def bridge(bridge_bin, site):
    return subprocess.run([str(bridge_bin), "--site", str(site), "--replay", "/dev/null"],
                          capture_output=True, text=True, timeout=20)


def site_with_period(tmp_path, name, period_s):
    src = f"{SCENARIOS}/{name}.ini"
    text = open(src).read()
    text, n = re.subn(r"(?m)^period_s = .*$", f"period_s = {period_s}", text, count=1)
    assert n == 1
    p = tmp_path / f"{name}-short.ini"
    p.write_text(text)
    line = next(i for i, ln in enumerate(text.splitlines(), 1) if ln.startswith("period_s"))
    return p, line


def needed_ms(site, distance_m):
    """2 x the longest flight, distance / (s - 3 sigma_s) (Kleeman 1992 eq. 19): the
    sequencer's window one firing after beacon 1 without knowing where the robot is."""
    s_min = site.speed_of_sound_mps - 3 * site.sigma_speed_of_sound_mps
    return 2 * distance_m / s_min * 1e3


def test_hearing_range_names_the_cause(bridge_bin, tmp_path):
    site = load_scenario("big-site").site
    assert site.hearing_range_m == 15.0
    bad, line = site_with_period(tmp_path, "big-site", 0.03)
    p = bridge(bridge_bin, bad)
    assert p.returncode == 78, p.stderr
    m = re.search(rf"{re.escape(str(bad))}:{line}: \[beacons\] period_s: hearing range 15 m needs "
                  r"(\d+) ms per beacon \(2 x ([\d.]+) ms flight \+ margins\); period 0.03 s too short",
                  p.stderr)
    assert m, p.stderr
    flight2 = needed_ms(site, 15.0)
    assert abs(2 * float(m.group(2)) - flight2) < 0.2
    # the margins: the arrival-noise margin and the period tolerance, a few ms
    assert flight2 < int(m.group(1)) < flight2 + 10
    # the period it names is accepted, a little less is not
    ok, _ = site_with_period(tmp_path, "big-site", int(m.group(1)) / 1e3 + 0.001)
    assert bridge(bridge_bin, ok).returncode == 0
    short, _ = site_with_period(tmp_path, "big-site", int(m.group(1)) / 1e3 - 0.002)
    assert bridge(bridge_bin, short).returncode == 78


def test_without_hearing_range_names_the_beacon_distance(bridge_bin, tmp_path):
    bad, line = site_with_period(tmp_path, "kleeman-lab", 0.08)
    p = bridge(bridge_bin, bad)
    assert p.returncode == 78, p.stderr
    m = re.search(rf"{re.escape(str(bad))}:{line}: \[beacons\] period_s: largest beacon distance "
                  r"([\d.]+) m \(no \[beacons\] hearing_range_m\) needs (\d+) ms per beacon", p.stderr)
    assert m, p.stderr
    site = load_scenario("kleeman-lab").site
    b = site.beacons_m
    d = max(((b[i, 0] - b[k, 0]) ** 2 + (b[i, 1] - b[k, 1]) ** 2) ** 0.5
            for i in range(len(b)) for k in range(len(b))) + site.ring_radius_m
    assert abs(float(m.group(1)) - d) < 0.06
    assert needed_ms(site, d) < int(m.group(2)) < needed_ms(site, d) + 10


def test_dense_sites_are_accepted(bridge_bin):
    # issue 14's targets, refused before the hearing range: 16 beacons at 0.10 s
    # in a 12 m room, 8 beacons at 0.15 s in a 24 m x 12 m hall, 12 at 0.12 s on 30 m
    for name in ("dense-room", "hall", "big-site"):
        p = bridge(bridge_bin, f"{SCENARIOS}/{name}.ini")
        assert p.returncode == 0, f"{name}: {p.stderr}"
