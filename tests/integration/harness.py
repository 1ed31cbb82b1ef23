"""Harness of the integration suite: the real bridge binary and the real
simulator on a kernel CAN bus, the bridge's MAVLink read with pymavlink.

Nothing here writes into the repository (it is read-only inside the VM):
every file goes to the test's own folder.
"""
from __future__ import annotations

import csv
import importlib
import json
import math
import os
import select
import signal
import socket
import struct
import subprocess
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402  (MAVLINK20 must be set first)

from beaconloc_sim.udp import widen_receive_buffer  # noqa: E402

REPO = Path(__file__).resolve().parents[2]
BUILD = Path(os.environ.get("BL_BUILD", REPO / "build"))
BRIDGE = BUILD / "bridge" / "beaconloc-bridge"
SIM = REPO / ".venv" / "bin" / "beaconloc-sim"
SCENARIOS = REPO / "hw_sim" / "beaconloc_sim" / "data" / "scenarios"
SITE = SCENARIOS / "kleeman-lab.ini"
DBC = REPO / "hw_sim" / "beaconloc_sim" / "data" / "beaconloc.dbc"

# MAVLink enum values the bridge must send (common.xml, from pymavlink).
MAV_FRAME_LOCAL_FRD = mavutil.mavlink.MAV_FRAME_LOCAL_FRD
MAV_FRAME_BODY_FRD = mavutil.mavlink.MAV_FRAME_BODY_FRD
MAV_ESTIMATOR_TYPE_VISION = mavutil.mavlink.MAV_ESTIMATOR_TYPE_VISION
MAV_TYPE_ONBOARD_CONTROLLER = mavutil.mavlink.MAV_TYPE_ONBOARD_CONTROLLER
MAV_AUTOPILOT_INVALID = mavutil.mavlink.MAV_AUTOPILOT_INVALID

NODE_CLOCK_WRAP_US = 1 << 32  # DBC: NodeTime wraps at 2^32 us


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


# The daemon under test runs ahead of the test's own Python (the checks of a
# finished case, the listeners of the others) on the guest's one CPU, as a
# robot's onboard computer would run it ahead of its other work. Needs root
# (the suite runs as root in the guest); without it the bridge runs at 0.
BRIDGE_NICE = -5


def _renice(nice: int) -> None:
    try:
        os.setpriority(os.PRIO_PROCESS, 0, nice)
    except OSError:
        pass


def tail(path: Path, n_chars: int = 4000) -> str:
    try:
        return path.read_text(errors="replace")[-n_chars:]
    except FileNotFoundError:
        return f"({path.name} missing)"


# --------------------------------------------------------------------------
# MAVLink side
# --------------------------------------------------------------------------

@dataclass
class Received:
    t_mono_s: float    # CLOCK_MONOTONIC when the datagram reached the socket
                       # (the kernel's receive timestamp), s
    msg: object
    t_parsed_s: float  # CLOCK_MONOTONIC when this process parsed it, s


# SO_TIMESTAMPNS (asm-generic/socket.h; Python's socket module may lack the name)
SO_TIMESTAMPNS = getattr(socket, "SO_TIMESTAMPNS", 35)


class MavlinkListener:
    """Receives the bridge's udpout stream on udpin:127.0.0.1:PORT in a
    thread; keeps every message with the kernel's receive time of its
    datagram (SO_TIMESTAMPNS), so what is measured is when the bridge's
    output arrived, not when this Python process got round to it: in the UML
    guest the test process alone is at times held up for most of a second
    while the bridge and the simulator run on. Replies (TIMESYNC requests)
    go back to the sender, as udpin does."""

    def __init__(self, port: int):
        self.port = port
        self.conn = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}",
                                               source_system=255, source_component=190)
        # MAVLink 2 whatever MAVLINK20 was when pymavlink was first imported in
        # this process (a test module collected before this one may have done
        # it without): parse_buffer below, unlike recv_match, never switches
        # (mavutil's auto_mavlink_version), and a MAVLink 1 parser reads the
        # bridge's MAVLink 2 frames as BAD_DATA.
        if self.conn.WIRE_PROTOCOL_VERSION != "2.0":
            v2 = importlib.import_module(f"pymavlink.dialects.v20.{mavutil.current_dialect}")
            self.conn.mav = v2.MAVLink(self.conn, srcSystem=255, srcComponent=190)
            self.conn.WIRE_PROTOCOL_VERSION = "2.0"
        self.sock = self.conn.port
        self.sock.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
        # Room for seconds of the stream while this process is held up (a
        # replay at 20x sends ~2400 ODOMETRY/s; the default buffer, ~200 KiB
        # of kernel memory, held 0.1 s of it and a busy host lost a quarter).
        widen_receive_buffer(self.sock)
        self.received: list[Received] = []
        self.bad_data = 0
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _kernel_mono_s(self, ancdata) -> float | None:
        for level, kind, data in ancdata:
            if level == socket.SOL_SOCKET and kind == SO_TIMESTAMPNS and len(data) >= 16:
                sec, nsec = struct.unpack("qq", data[:16])
                return sec + nsec * 1e-9 - real_minus_mono_s()
        return None

    def _run(self) -> None:
        while not self._stop.is_set():
            ready, _, _ = select.select([self.sock], [], [], 0.2)
            if not ready:
                continue
            try:
                data, ancdata, _flags, addr = self.sock.recvmsg(65535, 256)
            except OSError:
                continue
            parsed = time.monotonic()
            t_rx = self._kernel_mono_s(ancdata)
            # replies go back to the sender, as pymavlink's udpin records it
            self.conn.clients.add(addr)
            self.conn.clients_last_alive[addr] = time.time()
            msgs = self.conn.mav.parse_buffer(data) or []
            for msg in msgs:
                if msg.get_type() == "BAD_DATA":
                    self.bad_data += 1
                    continue
                with self._lock:
                    self.received.append(Received(parsed if t_rx is None else t_rx, msg, parsed))

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2)
        self.conn.close()

    def messages(self, mtype: str, since: float = 0.0) -> list[Received]:
        with self._lock:
            return [r for r in self.received if r.msg.get_type() == mtype and r.t_mono_s >= since]

    def wait_for(self, mtype: str, timeout_s: float, since: float = 0.0,
                 pred=lambda m: True) -> Received | None:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            for r in self.messages(mtype, since):
                if pred(r.msg):
                    return r
            time.sleep(0.05)
        return None

    def send_timesync(self, ts1: int) -> None:
        self.conn.mav.timesync_send(0, ts1)


def rate_hz(times_s: list[float]) -> float:
    """Mean message rate over a list of receive times, Hz."""
    if len(times_s) < 2:
        return 0.0
    return (len(times_s) - 1) / (times_s[-1] - times_s[0])


def real_minus_mono_s() -> float:
    """CLOCK_REALTIME - CLOCK_MONOTONIC now. The kernel (SO_TIMESTAMPNS, python-can)
    stamps receptions in realtime; a stamp is moved onto the monotonic clock by the
    difference of the two clocks read when it is handled, not once at the start: a
    step of the realtime clock during a case (a guest's time sync: 0.12 s seen in a
    UML guest) would otherwise shift every later stamp and the clock map built from
    them (the bridge does the same, can_in.c)."""
    return time.time() - time.monotonic()


def max_gap_s(times_s: list[float]) -> float:
    if len(times_s) < 2:
        return math.inf
    return float(np.max(np.diff(np.asarray(times_s))))


# ODOMETRY back in the site frame: the one mapping of beaconloc_sim.mavframe
# (also beaconloc-view's), re-exported for the cases and the demo.
from beaconloc_sim.mavframe import odometry_site_pos_cov, odometry_site_xy  # noqa: E402,F401


# --------------------------------------------------------------------------
# CAN side: the receiver-array node clock, seen from the bus
# --------------------------------------------------------------------------

class NodeClockProbe:
    """Listens on the bus (python-can, a socket of its own) and records, for
    every frame of the truth's time base (PULSE_DETECTION: the receiver
    array; BEARING on a site without ultrasonic beacons: the bearing sensor;
    RANGE on a site of range beacons only: the range receiver, whose frame
    leaves TimeOfFlight after its NodeTime, the emission: that flight is
    taken off the receive time, as the bridge does),
    the node time (decoded with cantools from the DBC) and the kernel
    receive time. The lower envelope of (receive - node) maps CLOCK_MONOTONIC
    to the node clock, the time base of the truth CSV, so the bridge's
    ODOMETRY (stamped on CLOCK_MONOTONIC) can be compared with the truth
    independently of the bridge's own estimates file.

    by: a signal of the frame that names whose clock NodeTime is (a team's
    TRACK_ENCODERS: Robot, each robot on its own clock): one mapping per
    value of it, mapping(value)."""

    def __init__(self, iface: str, frame: str = "PULSE_DETECTION", by: str | None = None):
        import can
        import cantools
        self._db = cantools.database.load_file(str(DBC))
        self.frame = frame
        self._pulse = self._db.get_message_by_name(frame)
        ours = [{"can_id": m.frame_id, "can_mask": 0x7FF} for m in self._db.messages]
        self.bus = can.Bus(interface="socketcan", channel=iface, can_filters=ours,
                           receive_own_messages=False)
        self.first_rx_mono_s: float | None = None  # first frame of any of our ids
        self.by = by
        self.rx_mono_s: list[float] = []
        self.node_us: list[int] = []
        self.keys: list[int | None] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            msg = self.bus.recv(timeout=0.2)
            if msg is None:
                continue
            if self.first_rx_mono_s is None:
                self.first_rx_mono_s = msg.timestamp - real_minus_mono_s()
                # From now on only the frames the clock map needs: the kernel
                # drops the rest before they wake this thread (every wake-up
                # costs about a millisecond of the UML guest's one CPU).
                self.bus.set_filters([{"can_id": self._pulse.frame_id, "can_mask": 0x7FF}])
            if msg.arbitration_id != self._pulse.frame_id or msg.dlc != 8:
                continue
            try:
                sig = self._pulse.decode(msg.data)
            except Exception:  # a malformed frame of a fault test
                continue
            tof_s = float(sig.get("TimeOfFlight", 0)) * 1e-6
            self.rx_mono_s.append(msg.timestamp - tof_s - real_minus_mono_s())
            self.node_us.append(int(sig["NodeTime"]))
            self.keys.append(int(sig[self.by]) if self.by else None)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2)
        self.bus.shutdown()

    def mapping(self, key: int | None = None):
        """Returns f(mono_s) -> node-clock us (unwrapped like the truth CSV:
        from the first frame's value, +2^32 per wrap), or None; key: whose
        clock (the `by` signal's value)."""
        mine = [i for i, k in enumerate(self.keys) if k == key]
        if len(mine) < 20:
            return None
        node = np.asarray(self.node_us, dtype=np.int64)[mine]
        wraps = np.concatenate([[0], np.cumsum(np.diff(node) < -(NODE_CLOCK_WRAP_US // 2))])
        node = node + wraps * NODE_CLOCK_WRAP_US
        rx_us = np.asarray(self.rx_mono_s)[mine] * 1e6
        # Lower envelope: per 5 s window the smallest (rx - node) is the
        # frame with the least queueing; a line through those minima gives
        # offset and drift.
        d = rx_us - node
        t = rx_us - rx_us[0]
        win = np.floor(t / 5e6).astype(int)
        xs, ys = [], []
        for w in np.unique(win):
            i = np.flatnonzero(win == w)
            j = i[np.argmin(d[i])]
            xs.append(rx_us[j])
            ys.append(d[j])
        if len(xs) >= 2:
            drift, offset = np.polyfit(np.asarray(xs) - xs[0], ys, 1)
        else:
            drift, offset = 0.0, ys[0]
        x0 = xs[0]

        def to_node_us(mono_s):
            m = np.asarray(mono_s, dtype=float) * 1e6
            return m - (offset + drift * (m - x0))
        return to_node_us


# --------------------------------------------------------------------------
# CSV files of the contracts
# --------------------------------------------------------------------------

TRUTH_COLUMNS = ("t_us,t_sim_s,x_m,y_m,theta_rad,v_mps,omega_radps,sos_mps,period_s,"
                 "temperature_c,pcrb_x_m,pcrb_y_m,pcrb_pos_m,pcrb_lateral_m,pcrb_sos_mps").split(",")
EST_COLUMNS = ("t_us,x_m,y_m,theta_rad,v_mps,omega_radps,sos_mps,period_s,var_x_m2,"
               "cov_xy_m2,var_y_m2,var_theta_rad2,reset_counter,quality").split(",")


def read_csv(path: Path, columns: list[str]) -> dict[str, np.ndarray]:
    """Columns of a CSV as float arrays (t_us as int64); checks the header."""
    with path.open(newline="") as fh:
        rows = list(csv.reader(fh))
    if not rows:
        raise AssertionError(f"{path}: empty")
    header = rows[0]
    missing = [c for c in columns if c not in header]
    assert not missing, f"{path}: columns {missing} missing from header {header}"
    body = [r for r in rows[1:] if r]
    out = {}
    for c in columns:
        k = header.index(c)
        if c == "t_us":
            out[c] = np.array([int(r[k]) for r in body], dtype=np.int64)
        else:
            out[c] = np.array([float(r[k]) if r[k] != "" else math.nan for r in body])
    return out


def truth_at(truth: dict, t_us: np.ndarray, col: str) -> np.ndarray:
    """Truth column interpolated at node-clock times (NaN outside the run)."""
    return np.interp(t_us, truth["t_us"], truth[col], left=np.nan, right=np.nan)


def wrap_angle(a):
    return (np.asarray(a) + np.pi) % (2 * np.pi) - np.pi


@dataclass
class Errors:
    """Estimate vs truth at the estimate times."""
    t_s: np.ndarray   # seconds since the truth's first row
    ex_m: np.ndarray
    ey_m: np.ndarray
    pos_m: np.ndarray
    mahal: np.ndarray  # Mahalanobis distance of (ex, ey) under the reported covariance
    quality: np.ndarray
    reset_counter: np.ndarray
    sos_err_mps: np.ndarray


def estimate_errors(est: dict, truth: dict) -> Errors:
    t = est["t_us"]
    ex = est["x_m"] - truth_at(truth, t, "x_m")
    ey = est["y_m"] - truth_at(truth, t, "y_m")
    vxx, vxy, vyy = est["var_x_m2"], est["cov_xy_m2"], est["var_y_m2"]
    det = vxx * vyy - vxy * vxy
    with np.errstate(invalid="ignore", divide="ignore"):
        # d^2 = e^T P^-1 e for the 2x2 position block.
        d2 = (vyy * ex * ex - 2 * vxy * ex * ey + vxx * ey * ey) / det
    return Errors(
        t_s=(t - truth["t_us"][0]) / 1e6, ex_m=ex, ey_m=ey, pos_m=np.hypot(ex, ey),
        mahal=np.sqrt(d2), quality=est["quality"], reset_counter=est["reset_counter"],
        sos_err_mps=est["sos_mps"] - truth_at(truth, t, "sos_mps"))


# --------------------------------------------------------------------------
# Processes
# --------------------------------------------------------------------------

@dataclass
class Proc:
    name: str
    popen: subprocess.Popen
    stderr_path: Path
    stdout_path: Path

    def alive(self) -> bool:
        return self.popen.poll() is None

    def stop(self, sig=signal.SIGTERM, timeout_s: float = 10.0) -> int:
        if self.popen.poll() is None:
            self.popen.send_signal(sig)
            try:
                self.popen.wait(timeout=timeout_s)
            except subprocess.TimeoutExpired:
                self.popen.kill()
                self.popen.wait()
        return self.popen.returncode


@dataclass(repr=False)
class Rig:
    """One test's bus, bridge, simulator and MAVLink listener."""
    workdir: Path
    iface: str                 # the simulator's (the sensor nodes') bus
    port: int = field(default_factory=free_udp_port)
    bridge_iface: str = ""     # the bridge's interface; default: iface
    procs: list = field(default_factory=list)
    listener: MavlinkListener | None = None
    probe: NodeClockProbe | None = None

    # files
    @property
    def estimates(self) -> Path:
        return self.workdir / "est.csv"

    @property
    def bridge_stats(self) -> Path:
        return self.workdir / "bridge-stats.json"

    @property
    def truth(self) -> Path:
        return self.workdir / "truth.csv"

    @property
    def sim_stats(self) -> Path:
        return self.workdir / "sim-stats.json"

    def __repr__(self) -> str:
        return f"Rig({self.workdir.name}, {self.iface})"

    def listen(self) -> MavlinkListener:
        if self.listener is None:
            self.listener = MavlinkListener(self.port)
        return self.listener

    def watch_node_clock(self, frame: str = "PULSE_DETECTION",
                         by: str | None = None) -> NodeClockProbe:
        """The probe of the truth's node clock, read from `frame`'s NodeTime
        (by: NodeClockProbe's, one clock per value of that signal)."""
        if self.probe is None:
            self.probe = NodeClockProbe(self.iface, frame, by)
        return self.probe

    def _spawn(self, name: str, argv: list[str], env: dict | None = None,
               nice: int = 0) -> Proc:
        out = self.workdir / f"{name}.out"
        err = self.workdir / f"{name}.err"
        p = subprocess.Popen(argv, cwd=self.workdir, stdin=subprocess.DEVNULL,
                             stdout=out.open("wb"), stderr=err.open("wb"),
                             env={**os.environ, **env} if env else None,
                             preexec_fn=(lambda: _renice(nice)) if nice else None)
        proc = Proc(name, p, err, out)
        self.procs.append(proc)
        return proc

    def start_bridge(self, site: Path = SITE, extra: list[str] | None = None,
                     name: str = "bridge", wait_heartbeat_s: float = 60.0,
                     env: dict | None = None) -> Proc:
        """Start the real daemon on this rig's bus (env: variables added to
        its environment); wait for its first HEARTBEAT so nothing the
        simulator sends afterwards is missed."""
        assert BRIDGE.exists(), f"{BRIDGE} not built (make all)"
        lst = self.listen()
        since = time.monotonic()
        p = self._spawn(name, [str(BRIDGE), "--site", str(site),
                               "--can", self.bridge_iface or self.iface,
                               "--mavlink", f"udpout:127.0.0.1:{self.port}",
                               "--estimates", str(self.workdir / f"{name}-est.csv"
                                                  if name != "bridge" else self.estimates),
                               "--stats", str(self.workdir / f"{name}-stats.json"),
                               *(extra or [])], env=env, nice=BRIDGE_NICE)
        if wait_heartbeat_s:
            hb = lst.wait_for("HEARTBEAT", wait_heartbeat_s, since=since)
            assert p.alive(), f"bridge exited {p.popen.returncode}:\n{tail(p.stderr_path)}"
            assert hb is not None, (f"no HEARTBEAT from the bridge within {wait_heartbeat_s} s:\n"
                                    f"{tail(p.stderr_path)}")
        return p

    def start_sim(self, scenario: str, duration_s: float | None = None,
                  seed: int | None = None, extra: list[str] | None = None) -> Proc:
        assert SIM.exists(), f"{SIM} missing (make setup)"
        # --spin-ms 0: the live cases run side by side on one guest CPU, where
        # simulators busy-waiting at SCHED_FIFO would starve the bridges.
        argv = [str(SIM), "run", scenario, "--channel", self.iface, "--spin-ms", "0",
                "--truth", str(self.truth), "--stats", str(self.sim_stats)]
        if duration_s is not None:
            argv += ["--duration", f"{duration_s:g}"]
        if seed is not None:
            argv += ["--seed", str(seed)]
        return self._spawn("sim", argv + (extra or []))

    def wait(self, proc: Proc, timeout_s: float) -> int:
        try:
            return proc.popen.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            raise AssertionError(f"{proc.name} still running after {timeout_s:.0f} s:\n"
                                 f"{tail(proc.stderr_path)}")

    def close(self) -> None:
        for p in self.procs:
            p.stop(signal.SIGTERM, timeout_s=5)
        if self.listener is not None:
            self.listener.close()
        if self.probe is not None:
            self.probe.close()

    def logs(self) -> str:
        parts = []
        for p in self.procs:
            parts.append(f"--- {p.name} (exit {p.popen.returncode}) stderr tail ---\n"
                         f"{tail(p.stderr_path)}")
        return "\n".join(parts)


def read_json(path: Path) -> dict:
    assert path.exists(), f"{path.name} was not written"
    return json.loads(path.read_text())


def sim_frames_sent(stats: dict) -> int:
    """Total frames the simulator put on the bus (its --stats JSON:
    "frames": {"0x100": n, ..., "total": n})."""
    frames = stats.get("frames")
    assert isinstance(frames, dict) and isinstance(frames.get("total"), int), (
        f"simulator stats have no frames.total: {stats}")
    return frames["total"]


# --------------------------------------------------------------------------
# One live run
# --------------------------------------------------------------------------

@dataclass(repr=False)
class LiveRun:
    rig: Rig
    scenario: str
    sim_rc: int
    bridge_rc: int | None
    t_sim_start_mono_s: float  # the simulator's first frame on the bus (CLOCK_MONOTONIC, s)
    t_sim_end_mono_s: float    # the simulator process ended
    timesync_sent: dict  # ts1 -> monotonic send time, s
    odometry: list
    heartbeats: list
    statustexts: list
    est: dict | None = None
    truth: dict | None = None
    bridge_stats: dict | None = None
    sim_stats: dict | None = None
    node_map: object = None
    probe: NodeClockProbe | None = None

    def __repr__(self) -> str:
        return f"LiveRun({self.scenario} on {self.rig!r})"

    def errors(self) -> Errors:
        assert self.est is not None, "the bridge wrote no --estimates CSV"
        return estimate_errors(self.est, self.truth)

    def statustext_lines(self) -> list[str]:
        return [r.msg.text for r in self.statustexts]

    def odometry_vs_truth(self):
        """(t_s since the truth start, error m, Mahalanobis distance under the
        ODOMETRY's own covariance, quality) for every ODOMETRY received,
        using the bus-derived mapping of CLOCK_MONOTONIC to the node clock."""
        assert self.node_map is not None, "too few frames of the truth's node clock on the bus"
        t_mono = np.array([r.msg.time_usec for r in self.odometry], dtype=float) / 1e6
        t_node = self.node_map(t_mono)
        xy = np.array([odometry_site_xy(r.msg) for r in self.odometry])
        ex = xy[:, 0] - truth_at(self.truth, t_node, "x_m")
        ey = xy[:, 1] - truth_at(self.truth, t_node, "y_m")
        mahal = np.full(len(ex), np.nan)
        for i, r in enumerate(self.odometry):
            cov = odometry_site_pos_cov(r.msg)
            if np.all(np.isfinite(cov)) and np.linalg.det(cov) > 0:
                e = np.array([ex[i], ey[i]])
                mahal[i] = math.sqrt(float(e @ np.linalg.solve(cov, e)))
        quality = np.array([r.msg.quality for r in self.odometry])
        return (t_node - self.truth["t_us"][0]) / 1e6, np.hypot(ex, ey), mahal, quality


def run_live(rig: Rig, scenario: str, duration_s: float, *, seed: int | None = None,
             site: Path = SITE, bridge_extra: list[str] | None = None,
             bridge_env: dict | None = None,
             actions: list | None = None, timesync_every_s: float = 0.0,
             stop_bridge: bool = True, clock_frame: str = "PULSE_DETECTION",
             clock_by: str | None = None, truth_columns=None, est_columns=None) -> LiveRun:
    """Bridge first (waits for its HEARTBEAT), then the simulator live on the
    rig's bus for duration_s; `actions` = [(seconds after the simulator
    started, callable(rig))] run in order; finally SIGTERM to the bridge.
    clock_frame: the frame whose NodeTime is the truth's clock (RANGE on a
    range-only site; BEARING on a
    site without ultrasonic beacons; a team's TRACK_ENCODERS with clock_by =
    "Robot": run.probe.mapping(robot) per robot, run.node_map None);
    truth_columns, est_columns: the CSVs' columns (default: one robot's)."""
    lst = rig.listen()
    rig.start_bridge(site=site, extra=bridge_extra, env=bridge_env)
    probe = rig.watch_node_clock(clock_frame, clock_by)
    sim = rig.start_sim(scenario, duration_s=duration_s, seed=seed)
    # Times count from the simulator's first frame on the bus (its start-up,
    # slow in an emulated VM, is not part of the scenario).
    launch_deadline = time.monotonic() + 240.0
    while probe.first_rx_mono_s is None:
        assert sim.alive(), f"simulator exited {sim.popen.returncode} before sending\n{rig.logs()}"
        assert time.monotonic() < launch_deadline, f"no frame from the simulator\n{rig.logs()}"
        time.sleep(0.05)
    t0 = probe.first_rx_mono_s
    pending = sorted(actions or [], key=lambda a: a[0])
    timesync_sent = {}
    next_ts = t0 + timesync_every_s if timesync_every_s else math.inf
    deadline = t0 + duration_s + 60.0
    while sim.alive():
        now = time.monotonic()
        assert now < deadline, f"simulator still running after {now - t0:.0f} s\n{rig.logs()}"
        while pending and now - t0 >= pending[0][0]:
            pending.pop(0)[1](rig)
        if now >= next_ts:
            ts1 = int(now * 1e9)
            timesync_sent[ts1] = now
            lst.send_timesync(ts1)
            next_ts = now + timesync_every_s
        time.sleep(0.05)
    t_end = time.monotonic()
    assert not pending, f"the simulator ended before the actions at {[a[0] for a in pending]} s"
    sim_rc = sim.popen.returncode
    time.sleep(1.0)  # the last frames through the bridge and UDP
    bridge_rc = None
    bridge = next((p for p in rig.procs if p.name == "bridge"), None)
    if stop_bridge and bridge is not None:
        bridge_rc = bridge.stop(signal.SIGTERM, timeout_s=15)
    time.sleep(0.3)
    run = LiveRun(rig=rig, scenario=scenario, sim_rc=sim_rc, bridge_rc=bridge_rc,
                  t_sim_start_mono_s=t0, t_sim_end_mono_s=t_end,
                  timesync_sent=timesync_sent,
                  odometry=lst.messages("ODOMETRY"), heartbeats=lst.messages("HEARTBEAT"),
                  statustexts=lst.messages("STATUSTEXT"),
                  node_map=None if clock_by else probe.mapping(), probe=probe)
    write_received(rig.workdir / "mavlink-rx.csv", run)
    assert sim_rc == 0, f"simulator exited {sim_rc}\n{rig.logs()}"
    run.truth = read_csv(rig.truth, truth_columns or TRUTH_COLUMNS)
    if rig.estimates.exists():
        run.est = read_csv(rig.estimates, est_columns or EST_COLUMNS)
    if rig.bridge_stats.exists():
        run.bridge_stats = read_json(rig.bridge_stats)
    if rig.sim_stats.exists():
        run.sim_stats = read_json(rig.sim_stats)
    return run


def write_received(path: Path, run: LiveRun) -> None:
    """The case's record of what the listener got: per message the kernel's
    receive time and the time this process parsed it (s after the
    simulator's first frame), its type, for ODOMETRY the bridge's time_usec,
    and the sender's MAVLink system id (a team's bridge sends one stream per
    robot); the simulator's end as the last row."""
    t0 = run.t_sim_start_mono_s
    with open(path, "w") as f:
        f.write("t_rx_s,t_parsed_s,type,time_usec,sysid\n")
        for r in list(run.rig.listener.received):
            kind = r.msg.get_type()
            tu = r.msg.time_usec if kind == "ODOMETRY" else ""
            f.write(f"{r.t_mono_s - t0:.6f},{r.t_parsed_s - t0:.6f},{kind},{tu},{r.msg.get_srcSystem()}\n")
        end = run.t_sim_end_mono_s - t0
        f.write(f"{end:.6f},{end:.6f},SIM_END,,\n")


def scenario_events(name: str, duration_s: float | None = None):
    """The simulator's own reading of a scenario file (fault times, duration)."""
    from beaconloc_sim.scenario import load_scenario as sim_load
    return sim_load(name, duration_s=duration_s)


BEACON_CYCLE_S = 6 * 0.150  # kleeman-lab: 6 beacons fired 150 ms apart
CONVERGED_AFTER_S = 20.0    # as the accuracy benchmark: judge after the first 20 s
