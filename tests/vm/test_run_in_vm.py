"""Host-side checks of the VM runner: it must never report success for a
suite that failed or did not run."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
import run_in_vm  # noqa: E402

RUNNER = Path(__file__).resolve().parent / "run_in_vm.py"

JUNIT = """<?xml version="1.0" encoding="utf-8"?>
<testsuites><testsuite name="pytest" errors="{errors}" failures="{failures}" skipped="{skipped}"
 tests="{tests}">
{cases}
</testsuite></testsuites>"""


def _junit(path: Path, cases: list[str], errors=0, failures=0, skipped=0) -> Path:
    path.write_text(JUNIT.format(errors=errors, failures=failures, skipped=skipped,
                                 tests=len(cases), cases="\n".join(cases)))
    return path


def test_report_counts_and_shows_each_failure_once(tmp_path, capsys):
    boom = '<failure message="boom">trace</failure><system-out>bridge log tail</system-out>'
    cases = ['<testcase classname="a" name="ok"/>',
             f'<testcase classname="a" name="f1">{boom}</testcase>',
             f'<testcase classname="a" name="f2">{boom}</testcase>',
             '<testcase classname="a" name="s"><skipped message="x"/></testcase>']
    tests, bad, summary = run_in_vm.report_junit(_junit(tmp_path / "j.xml", cases,
                                                        failures=2, skipped=1), 1000)
    out = capsys.readouterr().out
    assert (tests, bad) == (4, 2)
    assert summary == "1 passed, 2 failed, 1 skipped"
    assert out.count("bridge log tail") == 1 and "same failure as a::f1" in out


def test_report_missing_junit_counts_zero_tests(tmp_path):
    assert run_in_vm.report_junit(tmp_path / "none.xml", 100) == (0, 0, "no junit report")


def test_report_again_shows_every_guests_failures_last(tmp_path):
    """`make test` shows the vcan suite's failures again at its end (--report):
    each guest's failed cases by name with their message, the totals, and a
    non-zero exit; a guest without its report is named and counts as a failure;
    nothing is run and nothing in the results is removed."""
    r = tmp_path / "r"
    for g in ("guest0", "guest1", "guest2"):
        (r / g).mkdir(parents=True)
    _junit(r / "guest0" / "junit.xml", ['<testcase classname="t" name="ok"/>'])
    _junit(r / "guest1" / "junit.xml",
           ['<testcase classname="test_faults" name="test_stall">'
            '<failure message="AssertionError: ODOMETRY stopped for 0.61 s">trace</failure></testcase>',
            '<testcase classname="t" name="ok2"/>'], failures=1)
    report = [sys.executable, str(RUNNER), "--results", str(r), "--junit", "junit.xml", "--report"]
    p = subprocess.run(report, capture_output=True, text=True, timeout=60)
    assert p.returncode == 1, p.stdout + p.stderr
    assert "FAILED test_faults::test_stall" in p.stdout
    assert "ODOMETRY stopped for 0.61 s" in p.stdout
    assert "no junit report in: guest2" in p.stdout
    assert "FAILED guest1: test_faults::test_stall: AssertionError: ODOMETRY stopped for 0.61 s" in p.stdout
    assert p.stdout.rstrip().endswith("vcan suite: 2 passed, 1 failed, 0 skipped")
    assert (r / "guest1" / "junit.xml").exists()
    (r / "guest2").rmdir()
    _junit(r / "guest1" / "junit.xml", ['<testcase classname="t" name="ok2"/>'])
    p = subprocess.run(report, capture_output=True, text=True, timeout=60)
    assert p.returncode == 0, p.stdout + p.stderr
    assert "FAILED" not in p.stdout and "vcan suite: 2 passed, 0 failed, 0 skipped" in p.stdout


def _run(tmp_path, *args) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(RUNNER), "--results", str(tmp_path / "r"),
                           "--mode", "direct", *args], capture_output=True, text=True, timeout=120)


def test_direct_mode_without_a_bus_fails(tmp_path):
    """On a host without vcan, forcing direct mode must fail (exit 2, bus
    log shown), never pass the suite by not running it."""
    if run_in_vm.host_has_vcan():
        pytest.skip("this host has vcan: the bus comes up, nothing to refuse")
    p = _run(tmp_path, "--junit", "junit.xml", "true")
    assert p.returncode == 2, p.stdout + p.stderr
    assert "CAN bus could not be brought up" in p.stdout
    assert (tmp_path / "r" / "exit-code").read_text().strip() == "90"


def test_uml_kernel_has_its_can_modules():
    kernel, ver = run_in_vm.uml_kernel()
    mods = run_in_vm.UML_MODULES / ver / "kernel"
    for ko in ("net/can/can.ko", "net/can/can-raw.ko", "net/can/can-gw.ko",
               "drivers/net/can/dev/can-dev.ko", "drivers/net/can/vcan.ko"):
        assert (mods / ko).exists(), f"{mods / ko} missing: the guest could not load it"


def _run_uml(tmp_path, *command) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(RUNNER), "--results", str(tmp_path / "r"),
                           "--mode", "uml", "--memory", "512M", *command],
                          capture_output=True, text=True, timeout=300)


def test_uml_guest_runs_the_command_on_a_bus(tmp_path):
    """A real boot: the command runs in the guest on vcan0 with the results
    folder shared, and its exit status comes back."""
    out = tmp_path / "r" / "seen.txt"
    p = _run_uml(tmp_path, "sh", "-c",
                 f"uname -r > {out}; ip -o link show vcan0 >> {out}; exit 3")
    assert p.returncode == 1, p.stdout + p.stderr
    assert "command exited 3" in p.stdout
    seen = out.read_text()
    assert "vcan0" in seen and "UP" in seen
    assert "vcan round trip on vcan0: ok" in p.stdout


def test_uml_run_with_zero_tests_fails(tmp_path):
    """A suite that ran nothing is a failure, not a pass."""
    p = _run_uml(tmp_path, "--junit", "junit.xml", "true")
    assert p.returncode == 1, p.stdout + p.stderr
    assert "zero tests ran" in p.stdout


def test_uml_guests_side_by_side_each_run_their_shard(tmp_path):
    """--guests 2: two guests at once, each with its own results folder and
    BL_IT_SHARD; one failing guest fails the whole run."""
    p = _run_uml(tmp_path, "--guests", "2", "sh", "-c",
                 'echo "$BL_IT_SHARD" > "$BL_RESULTS/shard.txt"; [ "$BL_IT_SHARD" = 0/2 ]')
    r = tmp_path / "r"
    assert (r / "guest0" / "shard.txt").read_text().strip() == "0/2"
    assert (r / "guest1" / "shard.txt").read_text().strip() == "1/2"
    assert p.returncode == 1, p.stdout + p.stderr
    assert "guest1: FAILED: command exited 1" in p.stdout
    assert "guest0: FAILED" not in p.stdout
