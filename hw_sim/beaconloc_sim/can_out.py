"""CAN output: frames encoded by cantools from the project's DBC, written as a
candump log (python-can CanutilsLogWriter) or sent live on a python-can bus."""
from __future__ import annotations

import gc
import os
import time

import can
import numpy as np

from .dbc import database


def encode_all(frames) -> list[bytes]:
    """Payload of every frame, encoded by cantools.

    Every signal is first checked against its DBC range in one vectorised pass
    (a value out of range raises ValueError naming the frame and signal); cantools
    then encodes without repeating the per-frame check.
    """
    db = database()
    ids = frames.arb_id
    out: list[bytes] = [b""] * len(ids)
    for fid in sorted(set(ids.tolist())):
        msg = db.get_message_by_frame_id(fid)
        rows = np.flatnonzero(ids == fid).tolist()
        for sig in msg.signals:
            vals = np.array([frames.signals[i][sig.name] for i in rows], dtype=float)
            lo = sig.minimum if sig.minimum is not None else -np.inf
            hi = sig.maximum if sig.maximum is not None else np.inf
            raw = (vals - sig.offset) / sig.scale
            bad = (vals < lo) | (vals > hi) | (raw != np.round(raw))
            if bad.any():
                j = rows[int(np.argmax(bad))]
                raise ValueError(f"frame {j} ({msg.name}): signal {sig.name} = "
                                 f"{frames.signals[j][sig.name]} outside [{lo}, {hi}] or off-scale")
        for i in rows:
            out[i] = msg.encode(frames.signals[i], scaling=True, strict=False)
    return out


def messages(frames, epoch_s: float, channel: str):
    """python-can Messages with timestamp = epoch + simulated receive time (the bridge's clock)."""
    for t, fid, data in zip(frames.t_s.tolist(), frames.arb_id.tolist(), frames.data):
        yield can.Message(timestamp=epoch_s + t, arbitration_id=fid, is_extended_id=False,
                          data=data, channel=channel, is_rx=True)


def write_log(frames, path: str, epoch_s: float, channel: str) -> int:
    """candump -L format, as fast as possible. Returns the number of frames written."""
    with can.io.CanutilsLogWriter(path, channel=channel) as writer:
        return append_log(writer, frames, epoch_s, channel)


def append_log(writer: can.io.CanutilsLogWriter, frames, epoch_s: float, channel: str) -> int:
    """write_log onto an open writer (a run written window by window). Returns the count."""
    n = 0
    for msg in messages(frames, epoch_s, channel):
        writer.on_message_received(msg)
        n += 1
    return n


def realtime_priority(priority: int = 10) -> str:
    """Ask for SCHED_FIFO (needs root or CAP_SYS_NICE); returns the policy obtained."""
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
        return "SCHED_FIFO"
    except (AttributeError, OSError):
        return "SCHED_OTHER"


def send_live(frames, bus: can.BusABC, *, spin_s: float = 0.0015, stop=None) -> np.ndarray:
    """Send every frame at its simulated time, paced in real time.

    Absolute deadlines from one monotonic start instant (no drift accumulates):
    sleep until shortly before the deadline, then spin the last ``spin_s``.
    Messages are built beforehand and the garbage collector is paused while sending.
    Returns lateness of every frame (instant send() returned - deadline), s.
    """
    msgs = [can.Message(arbitration_id=fid, is_extended_id=False, data=data)
            for fid, data in zip(frames.arb_id.tolist(), frames.data)]
    deadlines_rel = frames.t_s.tolist()
    lateness = np.empty(len(msgs))
    clock = time.perf_counter
    gc_was_enabled = gc.isenabled()
    gc.disable()
    try:
        start = clock() + 0.05
        for i, msg in enumerate(msgs):
            if stop is not None and stop():
                return lateness[:i]
            deadline = start + deadlines_rel[i]
            remaining = deadline - clock()
            if remaining > spin_s:
                time.sleep(remaining - spin_s)
            while clock() < deadline:
                pass
            _send_retrying(bus, msg, deadline)
            lateness[i] = clock() - deadline     # the frame has left when send() returns
    finally:
        if gc_was_enabled:
            gc.enable()
    return lateness


def _send_retrying(bus: can.BusABC, msg: can.Message, deadline: float) -> None:
    """Send; on a full transmit queue (ENOBUFS) retry briefly, then give up with the error."""
    for attempt in range(50):
        try:
            bus.send(msg, timeout=0.01)
            return
        except can.CanOperationError:
            if attempt == 49:
                raise
            time.sleep(0.0002)
