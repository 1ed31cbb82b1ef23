"""The frame table, read from the DBC (the single source of truth for every frame):
frame ids, rolling-counter moduli and wrap moduli of the wrapping signals. Nothing
in the simulator writes a frame id or a modulus as a literal."""
from __future__ import annotations

import functools
from dataclasses import dataclass

import cantools

from .resources import dbc_path

COUNTER = "Counter"     # the rolling-counter signal of every frame that has one


@functools.lru_cache(maxsize=1)
def database() -> cantools.database.can.Database:
    return cantools.database.load_file(str(dbc_path()))


@dataclass(frozen=True)
class FrameSpec:
    name: str              # DBC message name
    frame_id: int          # 11-bit CAN identifier (also its arbitration priority: lower wins)
    counter_modulo: int    # the Counter signal counts 0 .. modulo - 1, then wraps (0: no Counter)


def signal_modulo(message: str, signal: str) -> int:
    """Number of values a wrapping unsigned signal takes: its DBC range max - min + 1
    (2^length when the DBC gives no range)."""
    sig = database().get_message_by_name(message).get_signal_by_name(signal)
    if sig.minimum is None or sig.maximum is None:
        return 1 << sig.length
    return int(round((sig.maximum - sig.minimum) / sig.scale)) + 1


@functools.lru_cache(maxsize=None)
def node_names() -> dict[int, str]:
    """NODE_STATUS NodeId -> the node's name, from the signal's DBC comment ("Sending node:
    1 receiver array, 2 wheel encoders, ...")."""
    comment = database().get_message_by_name("NODE_STATUS").get_signal_by_name("NodeId").comment
    items = comment.split(":", 1)[1].strip().rstrip(".").split(",")
    return {int(num): name.strip() for num, name in (item.strip().split(" ", 1) for item in items)}


@functools.lru_cache(maxsize=None)
def frame_spec(message: str) -> FrameSpec:
    msg = database().get_message_by_name(message)
    has_counter = any(s.name == COUNTER for s in msg.signals)
    return FrameSpec(message, msg.frame_id, signal_modulo(message, COUNTER) if has_counter else 0)


def frame_id(message: str) -> int:
    return frame_spec(message).frame_id


def message_names() -> dict[int, str]:
    """Every frame of the DBC, id -> name, in id order."""
    return {m.frame_id: m.name for m in sorted(database().messages, key=lambda m: m.frame_id)}
