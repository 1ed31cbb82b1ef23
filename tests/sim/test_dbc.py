"""The DBC round-trips every frame the simulator sends, and the log reads back."""
from __future__ import annotations

import random

import can
import cantools
import pytest

from beaconloc_sim import can_out, simulate
from beaconloc_sim.scenario import load_scenario
from beaconloc_sim.resources import dbc_path


@pytest.fixture(scope="module")
def echo_storm_run():
    return simulate.run(load_scenario("echo-storm", duration_s=40))


def test_every_simulated_frame_decodes_to_its_signals(echo_storm_run):
    db = cantools.database.load_file(str(dbc_path()))
    res = echo_storm_run
    assert {0x100, 0x110, 0x120} <= set(res.frames.arb_id.tolist())
    for fid, data, sig in zip(res.frames.arb_id.tolist(), res.frames.data, res.frames.signals):
        assert len(data) == 8
        decoded = db.decode_message(fid, data, decode_choices=False)
        assert decoded == sig


def test_every_dbc_message_round_trips_random_values():
    db = cantools.database.load_file(str(dbc_path()))
    rnd = random.Random(7)
    for msg in db.messages:
        for _ in range(200):
            values = {}
            for s in msg.signals:
                lo = 0 if s.minimum is None else round((s.minimum - s.offset) / s.scale)
                hi = (1 << s.length) - 1 if s.maximum is None else \
                    round((s.maximum - s.offset) / s.scale)
                values[s.name] = rnd.randint(lo, hi) * s.scale + s.offset
            decoded = msg.decode(msg.encode(values))
            assert decoded == values, msg.name


def test_rolling_counters_and_node_time(echo_storm_run):
    res = echo_storm_run
    by_key: dict = {}
    for fid, sig in zip(res.frames.arb_id.tolist(), res.frames.signals):
        by_key.setdefault((fid, sig.get("NodeId")), []).append(sig["Counter"])
    for (fid, _node), counters in by_key.items():
        mod = 8 if fid == simulate.ID_PULSE else 16
        assert all((b - a) % mod == 1 for a, b in zip(counters, counters[1:])), hex(fid)
    # the receiver-array clock starts 30 s before its 2^32 us wrap: NodeTime wraps in the run
    node_times = [s["NodeTime"] for fid, s in zip(res.frames.arb_id, res.frames.signals)
                  if fid == simulate.ID_PULSE]
    assert max(node_times) > 2**32 - 31_000_000 and min(node_times) < 20_000_000


def test_log_reads_back_with_python_can(tmp_path, echo_storm_run):
    res = echo_storm_run
    path = tmp_path / "run.log"
    n = can_out.write_log(res.frames, str(path), 1_700_000_000.0, "vcan0")
    assert n == len(res.frames)
    msgs = list(can.CanutilsLogReader(str(path)))
    assert len(msgs) == n
    for msg, t, fid, data in zip(msgs, res.frames.t_s, res.frames.arb_id.tolist(), res.frames.data):
        assert msg.arbitration_id == fid and bytes(msg.data) == data and msg.channel == "vcan0"
        assert msg.timestamp == pytest.approx(1_700_000_000.0 + t, abs=2e-6)
    stamps = [m.timestamp for m in msgs]
    assert stamps == sorted(stamps)


def test_frame_table_comes_from_the_dbc():
    """Every node kind's frame id and counter modulo are the DBC's, and no frame id or
    modulus is written as a literal in the simulator's code."""
    import re
    from pathlib import Path

    from beaconloc_sim import dbc, nodes
    db = cantools.database.load_file(str(dbc_path()))
    from beaconloc_sim.nodes.range_module import RangeModule
    from beaconloc_sim.nodes.track_encoders import TRACK_TICK_WRAP, TrackEncoders
    kinds = {*nodes.KINDS, RangeModule, TrackEncoders}
    for kind in kinds:
        msg = db.get_message_by_name(kind.message)
        counter = msg.get_signal_by_name("Counter")
        assert kind.frame_spec() == dbc.FrameSpec(msg.name, msg.frame_id, 1 << counter.length)
    assert {k.frame_spec().counter_modulo for k in kinds} == {8, 16}
    assert dbc.message_names() == {0x100: "PULSE_DETECTION", 0x110: "WHEEL_ENCODERS",
                                   0x120: "NODE_STATUS", 0x130: "RANGE", 0x131: "TRACK_ENCODERS",
                                   0x132: "TEAM_COMMAND", 0x133: "BEACON_SURVEY", 0x140: "BEARING",
                                   0x150: "SONAR", 0x170: "AIR_TEMPERATURE"}
    assert TRACK_TICK_WRAP == dbc.signal_modulo("TRACK_ENCODERS", "RightTicks") == 1 << 12
    from beaconloc_sim.clocks import WRAP_US
    from beaconloc_sim.encoders import TICK_WRAP
    assert TICK_WRAP == dbc.signal_modulo("WHEEL_ENCODERS", "RightTicks") == 1 << 14
    assert all(dbc.signal_modulo(m.name, "NodeTime") == WRAP_US
               for m in db.messages if "NodeTime" in [s.name for s in m.signals])
    package = Path(dbc.__file__).parent
    for path in sorted(package.rglob("*.py")):
        code = re.sub(r'""".*?"""|#[^\n]*', "", path.read_text(), flags=re.DOTALL)
        assert not re.search(r"\b(0x1[0-5][0-9a-fA-F]|256|272|288|304|307|320|336|1 << 14|\(1 << 3\))\b", code), path


def test_sonar_frame_layout_and_round_trip():
    """SONAR (0x150, issue 12): the shared interface's bit layout, and a reading with its flags
    round-trips through cantools."""
    db = cantools.database.load_file(str(dbc_path()))
    msg = db.get_message_by_name("SONAR")
    assert msg.frame_id == 0x150 and msg.length == 8 and msg.senders == ["SONAR_RING"]
    layout = {s.name: (s.start, s.length, s.scale, s.unit or "") for s in msg.signals}
    assert layout == {"NodeTime": (0, 32, 1, "us"), "Sensor": (32, 4, 1, ""),
                      "Range": (36, 14, 1, "mm"), "Amplitude": (50, 8, 1, ""),
                      "Flags": (58, 2, 1, ""), "Counter": (60, 4, 1, "")}
    assert all(not s.is_signed and s.byte_order == "little_endian" for s in msg.signals)
    reading = {"NodeTime": 4_294_000_123, "Sensor": 6, "Range": 2345, "Amplitude": 200,
               "Flags": 0, "Counter": 15}
    data = msg.encode(reading)
    assert msg.decode(data) == reading
    # the bits by hand: Range 2345 mm sits in bits 36..49, Flags MAX_RANGE (2) in 58..59
    word = int.from_bytes(data, "little")
    assert (word >> 36) & 0x3FFF == 2345 and (word >> 32) & 0xF == 6
    flagged = msg.encode(dict(reading, Flags=2, Range=0, Amplitude=0))
    assert (int.from_bytes(flagged, "little") >> 58) & 0x3 == 2
    assert msg.decode(flagged)["Flags"] == 2
