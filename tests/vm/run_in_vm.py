"""Run a command on a real kernel CAN bus: directly where the host has vcan,
otherwise inside one User-Mode Linux guest (Debian's user-mode-linux: the
guest kernel runs as host processes at native speed and boots in seconds).

    run_in_vm.py [options] COMMAND [ARGS...]
    run_in_vm.py --results DIR [--junit FILE] --report   (the last run's failures, again)

COMMAND runs with the repository as working directory, vcan0 up, and the
results folder in $BL_RESULTS. The guest shares the host's file system
(hostfs), so the results come back as they are written;
tests/vm/uml-init.sh is the guest's init, tests/vm/guest-init.sh brings up
the bus and runs the command in both modes.

Exit status: the command's own, or non-zero when it did not run at all
(the guest did not boot in time, no vcan, timeout, no exit code written) and,
with --junit, when the pytest report is missing or counts zero tests.
"""
from __future__ import annotations

import argparse
import concurrent.futures
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
import xml.etree.ElementTree as ET
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
GUEST_INIT = REPO / "tests" / "vm" / "guest-init.sh"


def log(msg: str) -> None:
    print(f"run-in-vm: {msg}", flush=True)


def host_has_vcan() -> bool:
    """True when this kernel can host a vcan bus (AF_CAN and the vcan driver)."""
    try:
        socket.socket(socket.AF_CAN, socket.SOCK_RAW, socket.CAN_RAW).close()
    except (OSError, AttributeError):
        return False
    if subprocess.run(["ip", "link", "show", "vcan0"], capture_output=True).returncode == 0:
        return True
    probe = f"blprobe{os.getpid() % 10000}"
    ok = subprocess.run(["ip", "link", "add", "dev", probe, "type", "vcan"],
                        capture_output=True).returncode == 0
    if ok:
        subprocess.run(["ip", "link", "del", "dev", probe], capture_output=True)
    return ok


UML_KERNEL = "linux.uml"  # Debian's user-mode-linux: /usr/bin/linux.uml
UML_MODULES = Path("/usr/lib/uml/modules")
UML_INIT = REPO / "tests" / "vm" / "uml-init.sh"


def uml_kernel() -> tuple[str, str]:
    """(path of linux.uml, its version) where its CAN modules are installed:
    the guest loads can, can-raw, can-dev, vcan and can-gw from
    /usr/lib/uml/modules/VERSION."""
    kernel = shutil.which(UML_KERNEL)
    if kernel is None:
        raise SystemExit("run-in-vm: linux.uml missing: install the Debian package "
                         "user-mode-linux (make setup)")
    found = sorted(d.name for d in UML_MODULES.glob("*")
                   if any((d / "kernel" / "drivers" / "net" / "can").glob("vcan.ko*")))
    if not found:
        raise SystemExit(f"run-in-vm: no vcan.ko under {UML_MODULES}/*/kernel/drivers/net/can "
                         "(package user-mode-linux)")
    return kernel, found[-1]


def uml_shim() -> str | None:
    """The LD_PRELOAD shim of tests/vm/uml_xstate.c (BL_UML_SHIM, as the
    Makefile builds it; else build/vm-shim/uml_xstate.so if built). UML 6.1
    panics without it where the host's XSAVE area is larger than it knows
    ("userspace - ptrace set fp regs failed, errno = 14": AVX-512, AMX)."""
    given = os.environ.get("BL_UML_SHIM")
    path = Path(given or REPO / "build" / "vm-shim" / "uml_xstate.so")
    if path.is_file():
        return str(path)
    if given:
        raise SystemExit(f"run-in-vm: BL_UML_SHIM={given} missing: build it with make")
    return None


def uml_argv(kernel: str, job: Path, memory: str) -> list[str]:
    """The UML command line: the host's own root file system over hostfs
    (read-write: results come back through it), uml-init.sh as PID 1, the
    job's path handed to init as the environment variable bl_job, the
    console on stdout."""
    return [kernel, f"mem={memory}", "root=/dev/root", "rootfstype=hostfs", "rootflags=/",
            "rw", f"init={UML_INIT}", f"bl_job={job}", "con=null", "con0=fd:0,fd:1"]


def clean_results(results: Path) -> None:
    results.mkdir(parents=True, exist_ok=True)
    for child in results.iterdir():
        if child.is_dir() and not child.is_symlink():
            shutil.rmtree(child)
        else:
            child.unlink()


def tail_new(path: Path, pos: int) -> int:
    """Print what was appended to path since byte pos; return the new pos."""
    try:
        with path.open("rb") as fh:
            fh.seek(pos)
            data = fh.read()
    except FileNotFoundError:
        return pos
    if data:
        sys.stdout.write(data.decode("utf-8", "replace"))
        sys.stdout.flush()
    return pos + len(data)


def kill_group(proc: subprocess.Popen) -> None:
    try:
        os.killpg(proc.pid, signal.SIGTERM)
        proc.wait(timeout=10)
    except (ProcessLookupError, subprocess.TimeoutExpired):
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        proc.wait()


def run(args: argparse.Namespace, results: Path, shard: str | None) -> tuple[str, int | None]:
    """Start the command (UML or direct); wait, tailing --tail; return
    (how it ended, exit code read from the results folder or None).
    shard: "I/N" for guest I of N side by side (BL_IT_SHARD), else None."""
    results.mkdir(parents=True, exist_ok=True)
    label = f"guest{shard.split('/')[0]}: " if shard else ""
    guest_cmd = [str(GUEST_INIT), str(results), *args.command]
    shim = uml_shim() if args.mode == "uml" else None
    env = dict(os.environ)
    env["PATH"] = f"{REPO / '.venv' / 'bin'}:{env.get('PATH', '')}"
    if args.ifaces:
        env["BL_VCAN_IFACES"] = args.ifaces
    if shard is not None:
        env["BL_IT_SHARD"] = shard
    if args.mode == "direct":
        log("host has vcan: running directly")
        argv = guest_cmd
        boot_timeout = None
    else:
        kernel, ver = uml_kernel()
        # The job: guest-init.sh and the command, with the host's environment
        # that matters (the guest's init starts with an empty one).
        keep = {k: v for k, v in env.items()
                if k in ("PATH", "BL_VCAN_IFACES", "BL_BUILD", "LANG", "LC_ALL", "TZ")
                or k.startswith("BL_IT_")}
        job = results / "job.sh"
        job.write_text("".join(f"export {k}={_shquote(v)}\n" for k, v in sorted(keep.items()))
                       + f"cd {_shquote(str(REPO))}\n"
                       + "exec " + " ".join(_shquote(a) for a in guest_cmd) + "\n")
        argv = uml_argv(kernel, job, args.memory)
        if shim is not None:
            env["LD_PRELOAD"] = shim
        log(f"{label}booting User-Mode Linux {ver} ({args.memory}); boot timeout "
            f"{args.boot_timeout:.0f} s")
        boot_timeout = args.boot_timeout
    console = (results / "console.log").open("wb")
    t_start = time.monotonic()
    proc = subprocess.Popen(argv, cwd=REPO, env=env, stdin=subprocess.DEVNULL,
                            stdout=console, stderr=subprocess.STDOUT,
                            start_new_session=True,
                            preexec_fn=lambda: _raise_priority(args.nice))
    tail_path = results / args.tail if args.tail and not label else None
    tail_pos = 0
    booted_at = None
    how = "finished"
    try:
        while proc.poll() is None:
            time.sleep(0.5)
            now = time.monotonic() - t_start
            if booted_at is None and (results / "booted").exists():
                booted_at = now
                if args.mode == "uml":
                    log(f"{label}guest booted after {now:.0f} s")
            if tail_path is not None:
                tail_pos = tail_new(tail_path, tail_pos)
            if boot_timeout is not None and booted_at is None and now > boot_timeout:
                how = f"guest did not boot within {boot_timeout:.0f} s"
                kill_group(proc)
                break
            if now > args.timeout:
                how = f"timed out after {args.timeout:.0f} s"
                kill_group(proc)
                break
    except KeyboardInterrupt:
        kill_group(proc)
        raise
    finally:
        console.close()
    if tail_path is not None:
        tail_new(tail_path, tail_pos)
    log(f"{label}{'guest' if args.mode == 'uml' else 'command'} ran {time.monotonic() - t_start:.0f} s")
    code_file = results / "exit-code"
    if not code_file.exists():
        if how == "finished":
            how = "the command never reported an exit code (guest crashed or never booted)"
            try:
                if b"ptrace set fp regs failed" in (results / "console.log").read_bytes():
                    how += ("; UML could not restore a task's FPU state: this host's XSAVE "
                            "area is larger than UML 6.1 knows (tests/vm/uml_xstate.c"
                            + (" was preloaded" if shim else
                               " was not preloaded: build it with make") + ")")
            except OSError:
                pass
        return how, None
    try:
        return how, int(code_file.read_text().strip())
    except ValueError:
        return "unreadable exit-code file", None


def _raise_priority(nice: int) -> None:
    """In the child before exec (after setsid): the test bus runs in real
    time, so it must not queue behind whatever else the host is busy with (a
    build, a fuzzer, another user's job). A guest is one host thread of
    execution; a nice value below the default lets it take its core when it
    needs it. With autogroup scheduling (/proc/sys/kernel/sched_autogroup_enabled)
    a process's nice only ranks it inside its own session, and sessions share
    the CPU as equals: the guest's session gets the same nice as its autogroup.
    Without the right to (not root, no CAP_SYS_NICE) the run goes on at the
    default."""
    if not nice:
        return
    try:
        os.setpriority(os.PRIO_PROCESS, 0, nice)
    except OSError:
        pass
    try:
        with open("/proc/self/autogroup", "w") as fh:
            fh.write(str(nice))
    except OSError:
        pass  # no autogroups in this kernel: the process nice is what counts


def _shquote(s: str) -> str:
    if s and all(c.isalnum() or c in "@%+=:,./-_" for c in s):
        return s
    return "'" + s.replace("'", "'\"'\"'") + "'"


def failed_cases(root: ET.Element):
    """(classname::name, the case, its failure or error element) of each failed case under root."""
    for case in root.iter("testcase"):
        bad = case.find("failure")
        if bad is None:
            bad = case.find("error")
        if bad is not None:
            yield f"{case.get('classname', '')}::{case.get('name', '')}", case, bad


def counts_of(tests: int, bad: int, summary: str) -> list[int]:
    """[passed, failed, skipped] from report_junit's result."""
    skipped = int(summary.split(", ")[2].split()[0]) if tests else 0
    return [tests - bad - skipped, bad, skipped]


def report_junit(path: Path, max_chars: int) -> tuple[int, int, str]:
    """Print failures with their logs and the summary; return (tests, bad, summary)."""
    if not path.exists():
        return 0, 0, "no junit report"
    root = ET.parse(path).getroot()
    suites = [root] if root.tag == "testsuite" else list(root.iter("testsuite"))
    tests = failures = errors = skipped = 0
    shown: dict[str, str] = {}  # failure text -> first case that showed it
    for s in suites:
        tests += int(s.get("tests", 0))
        failures += int(s.get("failures", 0))
        errors += int(s.get("errors", 0))
        skipped += int(s.get("skipped", 0))
        for name, case, bad in failed_cases(s):
            print(f"\n=============== FAILED {name} ===============")
            key = (bad.get("message") or "") + (bad.text or "")
            if key in shown:  # a module fixture's failure, once per case
                print(f"(same failure as {shown[key]})")
                continue
            shown[key] = name
            print((bad.get("message") or "")[:max_chars])
            print((bad.text or "")[-max_chars:])
            for tag in ("system-out", "system-err"):
                el = case.find(tag)
                if el is not None and el.text and el.text.strip():
                    print(f"--------------- {tag} ---------------")
                    print(el.text[-max_chars:])
    passed = tests - failures - errors - skipped
    summary = f"{passed} passed, {failures + errors} failed, {skipped} skipped"
    return tests, failures + errors, summary


def report_again(results: Path, junit: str, max_chars: int) -> int:
    """The failures of the run whose results are in `results` (one folder, or
    guest0..N-1 in it), shown again without running anything: `make test` runs
    the vcan suite beside the other suites and prints it first, so a CI log's
    tail would otherwise show only the others. Returns 1 if a case failed or a
    report is missing, else 0."""
    folders = sorted(results.glob("guest*")) or [results]
    counts, missing = [0, 0, 0], []
    print("\n=============== the vcan suite's failures, again ===============")
    for folder in folders:
        tests, bad, summary = report_junit(folder / junit, max_chars)
        if tests == 0:
            missing.append(folder.name)
            continue
        counts = [a + b for a, b in zip(counts, counts_of(tests, bad, summary))]
    # last, one line per failed case (a CI report may keep only a few lines)
    for folder in folders:
        if not (folder / junit).exists():
            continue
        for name, _case, bad in failed_cases(ET.parse(folder / junit).getroot()):
            message = (bad.get("message") or "").strip()
            first = message.splitlines()[0] if message else "(no message)"
            print(f"FAILED {folder.name}: {name}: {first[:300]}")
    if missing:
        print(f"no junit report in: {', '.join(missing)} (the suite did not run to its end there)")
    print(f"vcan suite: {counts[0]} passed, {counts[1]} failed, {counts[2]} skipped")
    return int(counts[1] > 0 or bool(missing))


def judge(args: argparse.Namespace, results: Path, how: str, code: int | None,
          label: str) -> tuple[int, list[int]]:
    """Print what one run left in its results folder; return (status: 0 ok,
    1 failed, 2 did not run; [passed, failed, skipped] of its junit report,
    zeros without one)."""
    counts = [0, 0, 0]
    bus_log = results / "bus.log"
    if code is None:
        log(f"{label}FAILED: {how}")
        for name in ("bus.log", "script.log", "console.log"):
            p = results / name
            if p.exists():
                print(f"--------------- {label}{name} (tail) ---------------")
                print(p.read_text(errors="replace")[-args.max_chars:])
        return 2, counts
    if code == 90:
        log(f"{label}FAILED: the CAN bus could not be brought up")
        print(bus_log.read_text(errors="replace") if bus_log.exists() else "(no bus.log)")
        return 2, counts
    failed = False
    if bus_log.exists():
        for line in bus_log.read_text(errors="replace").splitlines():
            if line.startswith("vcan round trip"):
                log(f"{label}{line}")
    if how != "finished":
        log(f"{label}FAILED: {how}")
        failed = True
    if args.junit:
        tests, bad, summary = report_junit(results / args.junit, args.max_chars)
        counts = counts_of(tests, bad, summary)
        script_log = results / "script.log"
        if tests == 0:
            log(f"{label}FAILED: {summary}: zero tests ran")
            if script_log.exists():
                print(script_log.read_text(errors="replace")[-args.max_chars:])
            failed = True
        log(f"{label}integration ({'UML' if args.mode == 'uml' else 'host vcan'}): {summary}")
        if bad:
            failed = True
    if code != 0:
        log(f"{label}FAILED: command exited {code} (log: {results / 'script.log'})")
        if not args.junit:
            p = results / "script.log"
            if p.exists():
                print(p.read_text(errors="replace")[-args.max_chars:])
        failed = True
    return int(failed), counts


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--results", default=str(REPO / "build" / "vm"),
                    help="results folder; emptied first")
    ap.add_argument("--mode", choices=("auto", "uml", "direct"), default="auto",
                    help="auto: direct where the host has vcan, else a UML guest")
    ap.add_argument("--guests", type=int, default=1,
                    help="UML guests side by side, each running the command with "
                         "BL_IT_SHARD=I/N and results in RESULTS/guestI (a UML guest has "
                         "one CPU: one guest per host core). Direct mode runs one command.")
    ap.add_argument("--boot-timeout", type=float, default=60.0, help="seconds")
    ap.add_argument("--timeout", type=float, default=1800.0,
                    help="seconds for boot plus command")
    ap.add_argument("--memory", default="2G", help="each guest's memory (UML mem=)")
    ap.add_argument("--nice", type=int, default=-10,
                    help="host nice value of the guests or the direct command (default -10: "
                         "ahead of the host's other work; needs root, else ignored)")
    ap.add_argument("--ifaces", default="", help="vcan interfaces to create (default vcan0)")
    ap.add_argument("--junit", default="", help="pytest junit xml (relative to results): "
                    "print its failures and summary, fail on zero tests")
    ap.add_argument("--tail", default="", help="file in results to show live")
    ap.add_argument("--max-chars", type=int, default=6000,
                    help="characters of each failure's log to print")
    ap.add_argument("--report", action="store_true",
                    help="run nothing: show again the failures the last run left in --results "
                         "(each guest's --junit report), e.g. at the end of a long log")
    ap.add_argument("command", nargs=argparse.REMAINDER)
    args = ap.parse_args()
    if args.report:
        return report_again(Path(args.results).resolve(), args.junit or "junit.xml", args.max_chars)
    if not args.command:
        ap.error("no command")
    if args.guests < 1:
        ap.error("--guests must be >= 1")
    results = Path(args.results).resolve()
    clean_results(results)
    if args.mode == "auto":
        args.mode = "direct" if host_has_vcan() else "uml"
    if args.mode == "direct" or args.guests == 1:
        how, code = run(args, results, None)
        status, counts = judge(args, results, how, code, "")
    else:
        n = args.guests
        folders = [results / f"guest{i}" for i in range(n)]
        with concurrent.futures.ThreadPoolExecutor(n) as pool:
            ends = list(pool.map(lambda i: run(args, folders[i], f"{i}/{n}"), range(n)))
        status, counts = 0, [0, 0, 0]
        for i, (how, code) in enumerate(ends):
            st, c = judge(args, folders[i], how, code, f"guest{i}: ")
            status = max(status, st)
            counts = [a + b for a, b in zip(counts, c)]
    if args.junit:
        print(f"{counts[0]} passed, {counts[1]} failed, {counts[2]} skipped")
    return status


if __name__ == "__main__":
    sys.exit(main())
