"""Issue 10's claim, end to end: a new sensor kind is six files and nothing else is edited.

The kind is a compass (an absolute heading sensor: a magnetometer, a ceiling camera's
heading), kept as fixtures in tests/kinds/compass/, never in the product tree:
  aid_compass.h, aid_compass.cpp   the library: params block, measurement, fusion through
                                   fuse_scalar, counters, hooks, its place in the kinds' list
  sensor_compass.c                 the bridge: handler, counters, status part
  compass.py                       the simulator: its node (a SensorKind)
  beaconloc.dbc.add                its frame COMPASS (0x160, BridgeKind 9) and node
  site_schema.toml.add             its section [compass] (count, sigma_deg, gate_sigma, rate_hz)
and, as its test, check_compass.c (its fusion against the closed form, no cmocka).

The test copies the tracked tree (the working tree's version of every file `git ls-files`
lists) into a temporary git repository, adds the four files and the two additions, checks
that exactly those six paths differ, builds the bridge there from nothing, simulates 30 s of
kleeman-lab with a compass through the copied simulator and replays the log through the
copied bridge twice: with the compass on the site and with [compass] count = 0. The stats
must show the compass frames decoded and fused by the library, none counted bad; the heading
with the compass must be within a few sigma of the truth and its sigma smaller than without.

In the copy the tree's own checks of its kinds run too (the site schema against the bridge
and the library, the DBC against the bridge's kinds, the counters' tables, the formatting of
the kind's C files), after `make docs-site-keys` regenerates docs/bridge.md's key table (a
generated doc, the only other file that changes). They pass but for the pins below: tests
that list today's kinds, sections or frames by design, which a new kind updates as its tests.
A check failing outside them is a shared file the kind would have to edit.
"""
from __future__ import annotations

import json
import math
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[2]
FIXTURES = Path(__file__).resolve().parent / "compass"
DBC = "hw_sim/beaconloc_sim/data/beaconloc.dbc"
SCHEMA = "hw_sim/beaconloc_sim/data/site_schema.toml"
SCENARIOS = "hw_sim/beaconloc_sim/data/scenarios"
# Where each fixture goes in the tree: the kind's four new files.
NEW_FILES = {
    "aid_compass.h": "lib/include/beaconloc/aid_compass.h",
    "aid_compass.cpp": "lib/src/aid_compass.cpp",
    "sensor_compass.c": "bridge/sensor_compass.c",
    "compass.py": "hw_sim/beaconloc_sim/nodes/compass.py",
}
# The six paths a new kind touches, and nothing else (issue 10).
KIND_PATHS = sorted([*NEW_FILES.values(), DBC, SCHEMA])
# Tests that pin today's kinds, sections or frames (a new kind updates them: its tests).
KNOWN_PINS = {
    # the schema's sections in file order: [compass] after [bridge]
    "tests/sim/test_site_schema.py::test_schema_sections_in_file_order",
    # nodes.KINDS by name: Compass after SonarRing
    "tests/sim/test_kinds.py::test_the_kinds_are_found_in_their_modules",
    # its toy kind is a compass too: section [compass] and clock keys compass_* are now known
    "tests/sim/test_kinds.py::test_a_kind_registered_in_a_test_needs_no_other_edit",
    # the frame ids: 0x160 COMPASS
    "tests/sim/test_dbc.py::test_frame_table_comes_from_the_dbc",
    # FRAME_KIND_COUNT == 10
    "build/tests/bridge/test_frame_kinds::test_numbers_stay",
    # the stats JSON and the status line byte for byte, every kind's keys and parts in them
    "build/tests/bridge/test_stats_log::test_json_report",
    "build/tests/bridge/test_stats_log::test_status_line_text",
    # the unknown-section message lists every section: [compass] at its end
    "build/tests/bridge/test_config::test_unknown_section",
}
# The tree's checks of its kinds run in the copy: pytest files, and cmocka executables
# (bridge: ASan/UBSan, as make test-bridge; lib: the default build).
SIM_CHECKS = ["tests/sim/test_site_schema.py", "tests/sim/test_kinds.py",
              "tests/sim/test_site_rule.py", "tests/sim/test_dbc.py", "tests/sim/test_config.py"]
BRIDGE_PY_CHECKS = ["tests/bridge/test_site_kind_sections.py"]
C_CHECKS = ["build/tests/bridge/test_frame_kinds", "build/tests/bridge/test_sensors",
            "build/tests/bridge/test_stats_log", "build/tests/bridge/test_site_rule",
            "build/tests/bridge/test_config", "build/lib/tests/test_config"]
COMPASS_ID = 0x160
SIGMA_DEG = 1.0          # [compass] sigma_deg of the run
DURATION_S = 30
GIT = ["git", "-c", "user.name=test", "-c", "user.email=test@localhost",
       "-c", "commit.gpgsign=false"]


def _run(cmd, cwd: Path, timeout: float, env=None) -> subprocess.CompletedProcess:
    p = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, timeout=timeout, env=env)
    assert p.returncode == 0, \
        f"{' '.join(map(str, cmd))} failed:\n{p.stdout[-3000:]}\n{p.stderr[-6000:]}"
    return p


def copy_tracked_tree(dst: Path) -> None:
    """The working tree's version of every tracked file (a file deleted in the working tree
    left out), as a git repository with one commit: a fresh clone's tree, build/ empty."""
    names = _run(["git", "ls-files", "-z"], REPO, 60).stdout.split("\0")
    for name in filter(None, names):
        src = REPO / name
        if not (src.is_file() or src.is_symlink()):
            continue
        (dst / name).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(src, dst / name, follow_symlinks=False)
    _run(["git", "init", "-q"], dst, 60)
    _run(GIT + ["add", "-A"], dst, 120)
    _run(GIT + ["commit", "-q", "-m", "tracked tree"], dst, 120)


def add_dbc_lines(text: str, add: str) -> str:
    """The DBC with the kind's lines: its node appended to BU_, its frame (BO_ and its SG_
    lines) after the last frame, each CM_ line after the last CM_ and each BA_ line after
    the last BA_ (the DBC's section order kept)."""
    lines = text.split("\n")

    def after_last(prefix: str) -> int:
        return max(i for i, line in enumerate(lines) if line.startswith(prefix)) + 1

    frame: list[str] = []
    for line in add.strip("\n").split("\n"):
        if line.startswith("BU_:"):
            i = after_last("BU_:") - 1
            lines[i] = lines[i].rstrip() + " " + line.split(":", 1)[1].strip()
        elif line.startswith(("BO_ ", " SG_ ")):
            frame.append(line)
        elif line.startswith(("CM_ ", "BA_ ")):
            lines.insert(after_last(line[:4]), line)
        else:
            raise ValueError(f"unexpected line in the DBC addition: {line!r}")
    i = after_last(" SG_ ")
    lines[i:i] = ["", *frame]
    return "\n".join(lines)


def add_kind(tree: Path) -> None:
    """The compass: its four files and its two additions, nothing else."""
    for fixture, path in NEW_FILES.items():
        shutil.copyfile(FIXTURES / fixture, tree / path)
    dbc = tree / DBC
    dbc.write_text(add_dbc_lines(dbc.read_text(), (FIXTURES / "beaconloc.dbc.add").read_text()))
    schema = tree / SCHEMA
    schema.write_text(schema.read_text() + (FIXTURES / "site_schema.toml.add").read_text())


def read_csv(path: Path) -> dict[str, np.ndarray]:
    data = np.genfromtxt(path, delimiter=",", names=True)
    return {name: data[name] for name in data.dtype.names}


def wrap(a):
    return (np.asarray(a) + np.pi) % (2 * np.pi) - np.pi


@pytest.fixture(scope="module")
def kind_tree(tmp_path_factory):
    """The tree with the compass added, its bridge built, a run simulated and replayed with
    and without the compass."""
    tree = tmp_path_factory.mktemp("tree")
    copy_tracked_tree(tree)
    add_kind(tree)
    _run(GIT + ["add", "-A"], tree, 120)
    changed = _run(GIT + ["diff", "--cached", "--name-status"], tree, 60).stdout
    stat = _run(GIT + ["diff", "--cached", "--stat"], tree, 60).stdout

    # The build: the tree's own .venv is this test's interpreter's (made by .ci/setup);
    # its setup stamp is not remade (-o: the copied files are newer than it).
    (tree / ".venv").symlink_to(Path(sys.prefix), target_is_directory=True)
    # the copy's simulator (before the editable install's), and none of an enclosing make's
    # settings (make test runs this under make: its jobserver, its BUILD)
    env = dict(os.environ, PYTHONPATH=str(tree / "hw_sim"))
    for name in ("BL_BUILD", "BUILD", "VENV", "MAKEFLAGS", "MFLAGS", "MAKELEVEL", "MAKEFILES"):
        env.pop(name, None)
    make = ["nice", "-n", "19", "make", "--no-print-directory", "-j2",
            "-o", ".venv/.beaconloc-setup"]
    _run(make + ["build/bridge/beaconloc-bridge", *C_CHECKS], tree, 1800, env)
    # the generated docs: docs/bridge.md's key table from the schema
    _run(make + ["docs-site-keys"], tree, 300, env)
    _run(GIT + ["add", "-A"], tree, 120)
    after_docs = _run(GIT + ["diff", "--cached", "--name-only"], tree, 60).stdout.split()

    # kleeman-lab with a compass on the robot
    run_dir = tmp_path_factory.mktemp("run")
    site_text = (tree / SCENARIOS / "kleeman-lab.ini").read_text()
    site = run_dir / "compass-lab.ini"
    site.write_text(site_text + f"\n[compass]\ncount = 1\nsigma_deg = {SIGMA_DEG}\nrate_hz = 10\n")
    no_compass = run_dir / "no-compass-lab.ini"
    no_compass.write_text(site_text + f"\n[compass]\ncount = 0\nsigma_deg = {SIGMA_DEG}\n")
    scn_text = (tree / SCENARIOS / "kleeman-lab.scenario.ini").read_text()
    scn_text, n = re.subn(r"(?m)^site = .*$", "site = compass-lab.ini", scn_text)
    assert n == 1
    scenario = run_dir / "compass-lab.scenario.ini"
    scenario.write_text(scn_text)
    log, truth = run_dir / "bus.log", run_dir / "truth.csv"
    sim = _run([sys.executable, "-m", "beaconloc_sim.cli", "run", str(scenario), "--log", str(log),
                "--truth", str(truth), "--duration", str(DURATION_S)], run_dir, 600, env)
    where = _run([sys.executable, "-c", "import beaconloc_sim; print(beaconloc_sim.__file__)"],
                 run_dir, 60, env).stdout.strip()

    bridge = tree / "build/bridge/beaconloc-bridge"
    replays = {}
    for name, site_file in (("compass", site), ("plain", no_compass)):
        est, stats = run_dir / f"{name}.est.csv", run_dir / f"{name}.stats.json"
        p = _run([str(bridge), "--site", str(site_file), "--replay", str(log),
                  "--mavlink", "udpout:127.0.0.1:9", "--estimates", str(est),
                  "--stats", str(stats)], run_dir, 600, env)
        replays[name] = dict(est=read_csv(est), stats=json.loads(stats.read_text()),
                             stderr=p.stderr)
    yield dict(tree=tree, env=env, changed=changed, stat=stat, after_docs=after_docs, log=log,
               truth=read_csv(truth), sim=sim, sim_module=where, replays=replays)
    shutil.rmtree(tree, ignore_errors=True)   # its build: tens of MB


def test_the_kind_is_six_files(kind_tree):
    """Exactly the four new files and the two additions differ from the tracked tree."""
    rows = [line.split("\t") for line in kind_tree["changed"].strip().split("\n")]
    assert sorted(path for _, path in rows) == KIND_PATHS, kind_tree["stat"]
    status = {path: st for st, path in rows}
    assert all(status[p] == "A" for p in NEW_FILES.values())
    assert status[DBC] == status[SCHEMA] == "M"
    # the simulator that ran is the copy's, with the kind's node in it
    assert Path(kind_tree["sim_module"]).is_relative_to(kind_tree["tree"])


def test_only_a_generated_doc_follows(kind_tree):
    """`make docs-site-keys` rewrites docs/bridge.md's key table for [compass]; nothing else
    (docs/mavlink.md's parameter table: the compass has no MAVLink parameter)."""
    assert sorted(kind_tree["after_docs"]) == sorted(KIND_PATHS + ["docs/bridge.md"])


def cmocka_failures(exe: str, cwd: Path) -> set[str]:
    """The failed tests of one cmocka executable (its path in the tree), as '<path>::<test>'."""
    env = dict(os.environ, ASAN_OPTIONS="detect_leaks=1",
               UBSAN_OPTIONS="halt_on_error=1:print_stacktrace=1")
    p = subprocess.run([str(cwd / exe)], cwd=cwd, capture_output=True, text=True, timeout=300,
                       env=env)
    out = p.stdout + p.stderr
    failed = {f"{exe}::{m}" for m in re.findall(r"(?m)^\[  FAILED  \] (\w+)$", out)}
    assert p.returncode == 0 or failed, f"{exe} crashed:\n{out[-4000:]}"
    return failed


def pytest_failures(files: list[str], tree: Path, env: dict) -> set[str]:
    p = subprocess.run([sys.executable, "-m", "pytest", "-q", "-rf", "-p", "no:cacheprovider",
                        *files], cwd=tree, capture_output=True, text=True, timeout=600, env=env)
    failed = set(re.findall(r"(?m)^(?:FAILED|ERROR) (\S+?)(?: - .*)?$", p.stdout))
    assert p.returncode in (0, 1), p.stdout[-4000:] + p.stderr[-4000:]
    assert p.returncode == 0 or failed, p.stdout[-4000:]
    return failed


def test_the_trees_own_checks_pass_but_for_the_pins(kind_tree):
    """The tree's checks of its kinds, run on the tree with the compass: every failure is one
    of the known pins (a test listing today's kinds), none is a check of a shared file."""
    tree, env = kind_tree["tree"], kind_tree["env"]
    failed = pytest_failures(SIM_CHECKS, tree, env) | pytest_failures(BRIDGE_PY_CHECKS, tree, env)
    for exe in C_CHECKS:
        failed |= cmocka_failures(exe, tree)
    assert failed <= KNOWN_PINS, sorted(failed - KNOWN_PINS)
    # the kind's C and C++ files as make check-format wants them
    p = subprocess.run(["clang-format", "--dry-run", "--Werror",
                        *(NEW_FILES[f] for f in NEW_FILES if not f.endswith(".py"))],
                       cwd=tree, capture_output=True, text=True)
    assert p.returncode == 0, p.stderr


def test_compass_fusion_is_the_closed_form(kind_tree):
    """check_compass.c (no cmocka) against the copy's library, linked as a pure C program
    (gcc ... -lm): the heading's update across the ±π wrap is the scalar Kalman update on θ,
    a later heading is compared with θ + ω·dt, the gate, the counters, the refusals."""
    tree = kind_tree["tree"]
    exe = tree / "build" / "check_compass"
    cc = os.environ.get("CC", "gcc")
    _run([cc, "-std=c11", "-D_GNU_SOURCE", "-Wall", "-Wextra", "-Werror", "-Ilib/include",
          "-Ibuild/gen/lib", str(FIXTURES / "check_compass.c"), "build/lib/libbeaconloc.a", "-lm",
          "-o", str(exe)], tree, 120)
    p = subprocess.run([str(exe)], capture_output=True, text=True, timeout=60)
    assert p.returncode == 0 and "check_compass: 0 failed" in p.stdout, p.stdout + p.stderr


def compass_frames(log: Path) -> int:
    return sum(1 for line in log.read_text().splitlines()
               if re.search(rf"\s{COMPASS_ID:03X}#", line))


def test_compass_frames_are_decoded_and_fused(kind_tree):
    """Every COMPASS frame of the log reaches the compass's handler; most are fused by the
    library (the rest before the filter's start or gated), none is counted bad."""
    n = compass_frames(kind_tree["log"])
    assert n >= 0.95 * 10 * DURATION_S
    s = kind_tree["replays"]["compass"]["stats"]
    assert s["frames_received"]["compass"] == n
    for key in ("malformed", "out_of_range", "lost_by_counter", "unknown_id", "replay_bad_lines",
                "compass_refused", "compass_unexpected", "stale_compass_samples"):
        assert s[key] == 0, (key, s[key])
    assert s["compass_fused"] >= 0.9 * n, s
    assert s["compass_rejected"] <= 0.02 * n, s
    assert (s["compass_fused"] + s["compass_rejected"] + s["compass_buffered"]
            + s["unmapped_compass"]) == n
    assert "compass ok" in kind_tree["replays"]["compass"]["stderr"]
    # the same log on a site without the compass: every frame counted unexpected, none fused
    p = kind_tree["replays"]["plain"]["stats"]
    assert p["compass_unexpected"] == n and p["compass_fused"] == 0


def heading_at_end(truth: dict, est: dict, last_s: float = 10.0):
    """The heading's errors (rad, wrapped) and sigmas (rad) of the estimates of the last
    last_s seconds (the truth interpolated on its unwrapped heading at each estimate's
    time, on the receiver-node clock both CSVs use)."""
    t_end = est["t_us"][-1]
    sel = est["t_us"] >= t_end - last_s * 1e6
    th = np.interp(est["t_us"][sel], truth["t_us"], np.unwrap(truth["theta_rad"]))
    return wrap(est["theta_rad"][sel] - th), np.sqrt(est["var_theta_rad2"][sel])


def test_heading_with_the_compass_is_near_the_truth_and_tighter(kind_tree):
    """With the compass the heading's error stays within a few of its sigma (which the
    compass bounds), and its sigma is smaller than the same run's without the compass."""
    truth = kind_tree["truth"]
    err, sigma = heading_at_end(truth, kind_tree["replays"]["compass"]["est"])
    err0, sigma0 = heading_at_end(truth, kind_tree["replays"]["plain"]["est"])
    assert len(err) > 100 and len(err0) > 100
    sigma_compass = math.radians(SIGMA_DEG)
    # the last estimate, and all of the last 10 s but a few
    assert abs(err[-1]) <= 3 * sigma[-1], (err[-1], sigma[-1])
    assert np.mean(np.abs(err) <= 3 * sigma) >= 0.95
    # the compass's own sigma bounds the heading's (10 headings per second of 1 degree)
    assert np.all(sigma <= sigma_compass), np.max(sigma)
    assert np.median(sigma) < 0.8 * np.median(sigma0), (np.median(sigma), np.median(sigma0))
    # and the heading is right: its rms error within the compass's sigma, and below the
    # same run's without the compass
    rms, rms0 = math.sqrt(np.mean(err ** 2)), math.sqrt(np.mean(err0 ** 2))
    assert rms <= sigma_compass and rms < rms0, (rms, rms0)
