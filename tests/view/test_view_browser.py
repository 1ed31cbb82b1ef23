"""beaconloc-view in a real browser: headless Chromium loads the page while the bridge
replays a simulator log paced (--speed 4), the test listens to the same MAVLink stream
(a second --mavlink endpoint of the bridge) and checks the page's DOM against it: the
robot's position, heading and 3-sigma ellipse against the last ODOMETRY (and the position
against the simulator's truth, which is in the site frame: a wrong FRD mapping fails it),
every beacon's state against the STATUSTEXT events, the latest event shown, the page's
update rate; and saves a screenshot into the test's folder. Polls with generous timeouts:
nothing depends on how fast this machine is."""
from __future__ import annotations

import math
import re
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from browser import Browser, chromium_path

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "tests" / "integration"))
sys.path.insert(0, str(REPO / "tests" / "bridge"))
import harness as h  # noqa: E402  (MavlinkListener, read_csv, TRUTH_COLUMNS)
from bridge_helpers import free_udp_port, run_sim  # noqa: E402
from view_rig import BRIDGE, start_replay, start_view, stop  # noqa: E402

SCENARIO = "beacon-outage"        # beacons 2 and 5 dead from 40 s: "beacon N lost" events
DURATION_S = 46
SPEED = 4                         # paced replay at 4x: 46 s of log in about 12 s
LOG_EPOCH_S = 1_700_000_000       # the scenario's [output] log_epoch_s: ODOMETRY time_usec
                                  # in replay is the log's clock = epoch + simulated time
BEACON_EVENT = re.compile(r"beacon (\d+) (lost|back)")


def robot_js(attr: str) -> str:
    return f"(() => {{ const g = document.getElementById('robot-1'); return g ? g.dataset.{attr} : null; }})()"


@pytest.fixture
def rig(tmp_path):
    if chromium_path() is None:
        pytest.fail("chromium missing: Debian package chromium (.ci/setup installs it)")
    if not BRIDGE.exists():
        pytest.fail(f"{BRIDGE} not built (make test-view builds it)")
    procs: list[subprocess.Popen] = []
    closers = []
    yield tmp_path, procs, closers
    for close in closers:
        close()
    for p in procs:
        stop(p)


def test_page_follows_the_bridge(rig):
    tmp, procs, closers = rig
    log, truth_csv = run_sim(tmp, SCENARIO, DURATION_S)
    view_port, test_port = free_udp_port(), free_udp_port()
    view, url = start_view(tmp, SCENARIO, view_port)
    procs.append(view)

    browser = Browser()
    closers.append(browser.close)
    browser.goto(url)
    n_beacons = browser.wait_for("document.querySelectorAll('.beacon').length", 60)
    assert n_beacons == 6, "kleeman-lab's six ultrasonic beacons"
    assert browser.evaluate("document.getElementById('site-name').textContent") == "kleeman-lab"

    listener = h.MavlinkListener(test_port)
    closers.insert(0, listener.close)
    bridge = start_replay(tmp, log, SPEED, [view_port, test_port])
    procs.append(bridge)
    # live: the robot appears while the replay runs
    assert browser.wait_for(robot_js("xM"), 60), "no robot drawn during the replay"
    assert bridge.poll() is None, "the replay ended before the page showed the robot"
    assert bridge.wait(timeout=120) == 0, (tmp / "bridge.out").read_text()[-2000:]

    odo = [r.msg for r in listener.messages("ODOMETRY")]
    texts = [r.msg.text for r in listener.messages("STATUSTEXT")]
    assert len(odo) > 30 * DURATION_S * 0.5
    # the page has taken in the whole stream: as many ODOMETRY as the listener
    count = browser.wait_for(f"(() => {{ const g = document.getElementById('robot-1'); "
                             f"return g && g.dataset.odometryCount == {len(odo)}; }})()", 30)
    assert count, (f"page saw {browser.evaluate(robot_js('odometryCount'))} ODOMETRY, "
                   f"the stream had {len(odo)}")
    time.sleep(0.5)  # one more update after the last message

    last = odo[-1]
    x_page = float(browser.evaluate(robot_js("xM")))
    y_page = float(browser.evaluate(robot_js("yM")))
    heading_page = math.radians(float(browser.evaluate(robot_js("headingDeg"))))
    # LOCAL_FRD x north, y east (docs/mavlink.md): site x east = ODOMETRY y
    assert x_page == pytest.approx(last.y, abs=1e-4)
    assert y_page == pytest.approx(last.x, abs=1e-4)
    # and the simulator's truth (site frame) at the estimate's time
    truth = h.read_csv(truth_csv, h.TRUTH_COLUMNS)
    t_sim = last.time_usec * 1e-6 - LOG_EPOCH_S
    tx, ty, tth = (np.interp(t_sim, truth["t_sim_s"], truth[c]) for c in ("x_m", "y_m", "theta_rad"))
    assert math.hypot(x_page - tx, y_page - ty) < 0.15, (x_page, y_page, tx, ty)
    dth = (heading_page - tth + math.pi) % (2 * math.pi) - math.pi
    assert abs(dth) < math.radians(10), (math.degrees(heading_page), math.degrees(tth))
    # 3-sigma ellipse: 3 sqrt of the eigenvalues of the horizontal covariance (a rotation
    # does not change them, so the FRD upper triangle gives the same)
    c = last.pose_covariance
    lam = np.linalg.eigvalsh(np.array([[c[0], c[1]], [c[1], c[6]]]))
    assert float(browser.evaluate(robot_js("ellipseAM"))) == pytest.approx(3 * math.sqrt(lam[1]), abs=2e-5)
    assert float(browser.evaluate(robot_js("ellipseBM"))) == pytest.approx(3 * math.sqrt(lam[0]), abs=2e-5)
    assert int(browser.evaluate(robot_js("quality"))) == last.quality

    # beacons: the state the stream's events give each, shown on the page
    lost = {}
    for t in texts:
        m = BEACON_EVENT.search(t)
        if m:
            lost[int(m.group(1))] = m.group(2) == "lost"
    assert any(lost.values()), f"{SCENARIO} should lose beacons: {texts}"
    assert not any("echo storm" in t for t in texts)
    states = browser.evaluate("Array.from(document.querySelectorAll('.beacon')).map("
                              "b => [b.dataset.kind, +b.dataset.n, b.dataset.state])")
    assert states == [["ultrasonic", n, "lost" if lost.get(n) else "heard"] for n in range(1, 7)]
    # the latest event is listed first
    shown = browser.evaluate("Array.from(document.querySelectorAll('#events li')).map(li => li.textContent)")
    assert shown and shown[0] == f"1: {texts[-1]}"
    sos = listener.messages("NAMED_VALUE_FLOAT")
    sos = [r.msg.value for r in sos if r.msg.name == "sos_mps"]
    assert float(browser.evaluate("document.getElementById('value-1-sos_mps').dataset.value")) \
        == pytest.approx(sos[-1], rel=1e-6)
    # trail: drawn, with points along the path (1 cm apart at most the path's length)
    points = int(browser.evaluate("document.getElementById('trail-1').dataset.points"))
    assert 100 < points
    # updates: the median time between two page updates (the server's 20 Hz); >= 10 Hz
    median_ms = float(browser.evaluate("document.getElementById('status').dataset.medianIntervalMs"))
    assert median_ms <= 100.0
    shot = tmp / "view.png"
    browser.screenshot(shot)
    assert shot.stat().st_size > 10_000
    print(f"view: {len(odo)} ODOMETRY, {points} trail points, median update interval "
          f"{median_ms:.1f} ms, screenshot {shot}")
