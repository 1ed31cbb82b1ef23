"""The beaconloc-sim command: run (log, truth, odometry, stats, live), plot, list; determinism."""
from __future__ import annotations

import csv
import json
import subprocess
import sys
import threading
from pathlib import Path

import can
import numpy as np
import pytest

from beaconloc_sim import cli

from conftest import site_with

TRUTH_HEADER = ("t_us,t_sim_s,x_m,y_m,theta_rad,v_mps,omega_radps,sos_mps,period_s,temperature_c,"
                "pcrb_x_m,pcrb_y_m,pcrb_pos_m,pcrb_lateral_m,pcrb_sos_mps").split(",")
EST_HEADER = ("t_us,x_m,y_m,theta_rad,v_mps,omega_radps,sos_mps,period_s,var_x_m2,cov_xy_m2,"
              "var_y_m2,var_theta_rad2,reset_counter,quality").split(",")
BIN = Path(sys.executable).with_name("beaconloc-sim")


def test_run_writes_parseable_log_truth_odometry_stats(tmp_path):
    out = {k: tmp_path / f"{k}" for k in ("log", "truth", "odo", "stats")}
    proc = subprocess.run([str(BIN), "run", "kleeman-lab", "--duration", "30", "--log", str(out["log"]),
                           "--truth", str(out["truth"]), "--odometry", str(out["odo"]),
                           "--stats", str(out["stats"])], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    msgs = list(can.CanutilsLogReader(str(out["log"])))
    stats = json.loads(out["stats"].read_text())
    assert stats["frames"]["total"] == len(msgs)
    for fid in (0x100, 0x110, 0x120):
        assert stats["frames"][f"0x{fid:03X}"] == sum(m.arbitration_id == fid for m in msgs)
    assert stats["frames"]["0x110"] == pytest.approx(30 * 100, abs=2)      # 100 Hz encoders
    assert stats["frames"]["0x120"] == pytest.approx(2 * 30, abs=2)       # 1 Hz from 2 nodes
    with open(out["truth"]) as fh:
        rows = list(csv.reader(fh))
    assert rows[0] == TRUTH_HEADER
    truth = np.array(rows[1:], dtype=float)
    assert len(truth) == 30 * 50 + 1
    t_us = truth[:, 0]
    assert np.all(np.diff(t_us) > 0) and t_us.max() > 2**32        # unwrapped across the wrap
    assert np.allclose(np.diff(truth[:, 1]), 0.02)
    assert np.all(truth[:, 12] > 0)
    with open(out["odo"]) as fh:
        assert next(csv.reader(fh)) == ["t_us", "x_m", "y_m", "theta_rad"]


def test_identical_seeds_give_identical_logs(tmp_path):
    logs = []
    for i, seed in enumerate((5, 5, 6)):
        path = tmp_path / f"{i}.log"
        assert cli.main(["run", "echo-storm", "--duration", "10", "--seed", str(seed),
                         "--log", str(path)]) == 0
        logs.append(path.read_bytes())
    assert logs[0] == logs[1]
    assert logs[0] != logs[2]


def test_bad_site_file_exits_78_naming_file_line_key(tmp_path, capsys):
    (tmp_path / "s.ini").write_text(site_with(beacon3__x_m="abc"))
    scn = tmp_path / "bad.scenario.ini"
    scn.write_text("[scenario]\nsite = s.ini\nduration_s = 1\n[path]\nstart = 1, 1, 0\n")
    assert cli.main(["run", str(scn), "--log", str(tmp_path / "x.log")]) == 78
    assert "s.ini:" in capsys.readouterr().err
    assert not (tmp_path / "x.log").exists()


def test_plot_writes_png(tmp_path):
    truth_p, odo_p = tmp_path / "truth.csv", tmp_path / "odo.csv"
    assert cli.main(["run", "kleeman-lab", "--duration", "20", "--truth", str(truth_p),
                     "--odometry", str(odo_p)]) == 0
    with open(truth_p) as fh:
        rows = list(csv.DictReader(fh))
    rng = np.random.default_rng(0)
    est_p = tmp_path / "est.csv"
    with open(est_p, "w") as fh:
        fh.write(",".join(EST_HEADER) + "\n")
        for r in rows[::2]:
            x = float(r["x_m"]) + rng.normal(0, 0.02)
            y = float(r["y_m"]) + rng.normal(0, 0.02)
            fh.write(f"{r['t_us']},{x},{y},{r['theta_rad']},{r['v_mps']},{r['omega_radps']},"
                     f"{float(r['sos_mps']) + 0.5},{r['period_s']},4e-4,0,4e-4,1e-3,0,50\n")
    out = tmp_path / "plot.png"
    assert cli.main(["plot", "--truth", str(truth_p), "--estimates", str(est_p),
                     "--odometry", str(odo_p), "--out", str(out)]) == 0
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and out.stat().st_size > 20_000
    bad = tmp_path / "bad.csv"
    bad.write_text("t_us,x_m\n1,2\n")
    assert cli.main(["plot", "--truth", str(truth_p), "--estimates", str(bad),
                     "--out", str(tmp_path / "p2.png")]) == 65


@pytest.mark.parametrize("spin_ms", ["1.5", "0"])
def test_live_on_virtual_bus_sends_every_frame(tmp_path, spin_ms):
    """Live mode over python-can's virtual interface; a second bus on the channel receives all,
    with the last 1.5 ms of each wait spun (the default) or slept (--spin-ms 0)."""
    channel = f"beaconloc-test-{id(tmp_path)}"
    rx = can.Bus(interface="virtual", channel=channel)
    got = []
    done = threading.Event()

    def reader():
        # until the sender is done and the channel drained: the last frames may still be
        # queued when the run returns (a busy machine: 179 of 181 read before the drain)
        while True:
            m = rx.recv(timeout=0.05)
            if m is not None:
                got.append(m)
            elif done.is_set():
                break
    th = threading.Thread(target=reader)
    th.start()
    stats_p = tmp_path / "stats.json"
    try:
        assert cli.main(["run", "kleeman-lab", "--duration", "1.5", "--channel", channel,
                         "--interface", "virtual", "--spin-ms", spin_ms,
                         "--stats", str(stats_p)]) == 0
    finally:
        done.set()
        th.join()
        rx.shutdown()
    stats = json.loads(stats_p.read_text())
    assert stats["live"]["frames_sent"] == stats["frames"]["total"] == len(got)
    assert {m.arbitration_id for m in got} == {0x100, 0x110, 0x120}
    lat = stats["live"]["lateness_us"]
    assert 0 <= lat["p50"] <= lat["p99"] <= lat["max"]


@pytest.mark.parametrize("spin_ms", ["-1", "nan", "1000"])
def test_live_spin_out_of_range_is_a_usage_error(spin_ms, capsys):
    assert cli.main(["run", "kleeman-lab", "--duration", "1", "--channel", "vcan0",
                     "--spin-ms", spin_ms]) == 64
    assert "--spin-ms" in capsys.readouterr().err


@pytest.mark.parametrize("window", [None, "4"])
def test_run_eurobot_writes_a_candump_log_of_bearing_frames_and_the_bound(tmp_path, window):
    """The bearing-only site through the command: every frame of the log decodes with cantools
    from the DBC, the bearing counters roll modulo 16, the truth carries the bound."""
    import cantools
    from beaconloc_sim.resources import dbc_path
    out = {k: tmp_path / f"{k}" for k in ("log", "truth", "odo", "stats")}
    args = [str(BIN), "run", "eurobot", "--log", str(out["log"]), "--truth", str(out["truth"]),
            "--odometry", str(out["odo"]), "--stats", str(out["stats"])]
    proc = subprocess.run(args + (["--window", window] if window else []), capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    db = cantools.database.load_file(str(dbc_path()))
    msgs = list(can.CanutilsLogReader(str(out["log"])))
    decoded = [(m.arbitration_id, db.decode_message(m.arbitration_id, m.data)) for m in msgs]
    bearing = [s for fid, s in decoded if fid == 0x140]
    stats = json.loads(out["stats"].read_text())
    # 121 scans (the node's clock is at a multiple of the 0.1 s scan period at t = 0), none lost
    assert len(bearing) == stats["frames"]["0x140"]
    assert stats["bearings"]["sent"] == stats["bearings"]["measured"] == 3 * 121
    # the last scan's frames are ready just before 12 s: a windowed run does not send those
    # that have not started by then
    if window is None:
        assert len(bearing) == 3 * 121
    else:
        assert 3 * 120 <= len(bearing) < 3 * 121
    assert stats["frames"]["0x100"] == 0
    assert np.all(np.diff([s["Counter"] for s in bearing]) % 16 == 1)
    assert {s["Beacon"] for s in bearing} == {1, 2, 3}
    with open(out["truth"]) as fh:
        rows = list(csv.reader(fh))
    truth = np.array(rows[1:], dtype=float)
    assert rows[0] == TRUTH_HEADER and len(truth) == 12 * 50 + 1
    assert np.all(np.diff(truth[:, 0]) > 0) and truth[:, 0].max() > 2**32   # bearing clock wraps
    assert np.all(truth[:, 12] > 0) and truth[-1, 12] < 0.01


@pytest.mark.parametrize("window", [None, "7"])
def test_run_marvelmind_writes_a_log_of_range_frames_truth_and_odometry(tmp_path, window):
    """The range-only site through the command: RANGE frames decode with cantools, their
    counters roll modulo 16, the stats count the pings, the truth carries the bound (on the
    range receiver's clock), the odometry is written."""
    import cantools
    from beaconloc_sim.resources import dbc_path
    out = {k: tmp_path / f"{k}" for k in ("log", "truth", "odo", "stats")}
    args = [str(BIN), "run", "marvelmind-multipath", "--duration", "20", "--log", str(out["log"]),
            "--truth", str(out["truth"]), "--odometry", str(out["odo"]), "--stats",
            str(out["stats"])]
    proc = subprocess.run(args + (["--window", window] if window else []), capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    db = cantools.database.load_file(str(dbc_path()))
    decoded = [(m.arbitration_id, db.decode_message(m.arbitration_id, m.data))
               for m in can.CanutilsLogReader(str(out["log"]))]
    ranges = [s for fid, s in decoded if fid == 0x130]
    stats = json.loads(out["stats"].read_text())
    assert len(ranges) == stats["frames"]["0x130"] == stats["ranges"]["sent"]
    assert stats["frames"]["0x100"] == 0
    # 400 pings in 20 s, 5 % dropouts, 10 % of the sent ones multipath
    assert 399 <= stats["ranges"]["pinged"] <= 401
    assert 0.01 < stats["ranges"]["dropout"] / stats["ranges"]["pinged"] < 0.10
    assert 0.04 < stats["ranges"]["multipath"] / stats["ranges"]["sent"] < 0.17
    assert np.all(np.diff([s["Counter"] for s in ranges]) % 16 == 1)
    assert {s["Beacon"] for s in ranges} == {1, 2, 3, 4}
    assert {s["NodeId"] for fid, s in decoded if fid == 0x120} == {2, 4}
    with open(out["truth"]) as fh:
        rows = list(csv.reader(fh))
    truth = np.array(rows[1:], dtype=float)
    assert rows[0] == TRUTH_HEADER and len(truth) == 20 * 50 + 1
    assert np.all(np.diff(truth[:, 0]) > 0)
    # the range clock (range_offset_us = 4 290 000 000) wraps 5 s into the run
    assert truth[0, 0] < 2**32 < truth[-1, 0]
    assert np.all(truth[25:, 12] < 0.05) and truth[0, 12] > 1.0
    with open(out["odo"]) as fh:
        odo = list(csv.reader(fh))
    assert len(odo) > 20 * 100


def test_bound_prior_is_the_estimators_start(tmp_path, capsys):
    """--bound-prior: the bound starts from the given sigma about the true start pose (the
    information a known start gives the estimator) and stays below the default prior's."""
    def pcrb(*extra):
        truth = tmp_path / "truth.csv"
        assert cli.main(["run", "eurobot", "--duration", "3", "--truth", str(truth), *extra]) == 0
        with open(truth) as fh:
            rows = list(csv.reader(fh))
        return np.array(rows[1:], dtype=float)[:, TRUTH_HEADER.index("pcrb_pos_m")]
    weak, known = pcrb(), pcrb("--bound-prior", "0.07,5")
    # after the first scan (t = 0): the prior and one triangulation in the poor lower-left
    # corner; the 7 cm prior dominates, the 1 m one does not
    assert 0.06 < known[0] < 0.07 * np.sqrt(2)
    assert 0.3 < weak[0] < np.sqrt(2)
    assert np.all(known <= weak + 1e-12) and known[-1] < weak[-1]
    for bad in ("0,5", "0.07", "0.07,0", "x,y", "0.07,361"):
        assert cli.main(["run", "eurobot", "--duration", "1", "--truth", str(tmp_path / "t"),
                         "--bound-prior", bad]) == 64
        assert "--bound-prior" in capsys.readouterr().err
