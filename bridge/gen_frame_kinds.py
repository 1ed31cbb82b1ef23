"""The bridge's sensor kinds, generated at build time from the DBC (bridge/bridge.mk).

    python bridge/gen_frame_kinds.py DBC OUTDIR

writes into OUTDIR (never committed):
  frame_kinds.h   enum frame_kind (FRAME_<FRAME NAME>, FRAME_KIND_COUNT); one payload
                  struct per kind (struct frame_<frame name>: one field per signal,
                  in DBC order, named after the signal and its unit); the union
                  members of struct frame; the unpackers' prototypes
  frame_kinds.c   frame_<frame name>_unpack(): the cantools-generated unpack, every
                  signal that can leave its DBC range checked, the payload filled, and
                  what the rolling-counter check needs (struct frame_seq: the
                  Counter signal; the stamp, the first signal in us or s)
  sensor_kinds.c  sensor_kinds[]: &sensor_kind_<frame name> of each kind, which its
                  own bridge/sensor_<kind>.c defines (a missing one fails the link)

A kind is a frame the bridge receives (a signal of it names BRIDGE as receiver);
its number is the frame's BridgeKind attribute in the DBC: given once, never
reused, the next free one for a new kind (the stats JSON and the status line
list the kinds in this order). A frame the bridge sends has none.
"""
from __future__ import annotations

import sys
from pathlib import Path

import cantools
from cantools.database.can.c_source import camel_to_snake_case as snake

ATTRIBUTE = "BridgeKind"
RECEIVER = "BRIDGE"
CODEC = "beaconloc_can"  # the cantools database name (bridge/bridge.mk)


def field_name(sig) -> str:
    """The payload field of a signal: its name with its unit (NodeTime, us ->
    node_time_us), unless the name already says it (LeftTicks, tick -> left_ticks)."""
    base = snake(sig.name)
    unit = (sig.unit or "").lower()
    if not unit or base.endswith("_" + unit) or base.endswith("_" + unit + "s"):
        return base
    return f"{base}_{unit}"


def raw_type(sig) -> str:
    """The C type cantools gives the raw signal."""
    bits = next(n for n in (8, 16, 32, 64) if sig.length <= n)
    return f"{'int' if sig.is_signed else 'uint'}{bits}_t"


def is_physical(sig) -> bool:
    """A signal whose value is not its raw integer: decoded into a double."""
    return sig.is_float or sig.scale != 1 or sig.offset != 0


def can_leave_range(sig) -> bool:
    """Whether the signal's raw value can lie outside its DBC range: a float, or
    a range narrower than what its bits hold. A check that cannot fail is left
    out (it would be a call per signal per frame on the receive path)."""
    if sig.is_float:
        return True
    if sig.minimum is None and sig.maximum is None:
        return False
    n = sig.length
    bit_lo, bit_hi = (-(1 << (n - 1)), (1 << (n - 1)) - 1) if sig.is_signed else (0, (1 << n) - 1)
    raw = sorted((v - sig.offset) / sig.scale for v in (
        bit_lo * sig.scale + sig.offset if sig.minimum is None else sig.minimum,
        bit_hi * sig.scale + sig.offset if sig.maximum is None else sig.maximum))
    return raw[0] > bit_lo + 1e-9 or raw[1] < bit_hi - 1e-9


def field_type(sig) -> str:
    if is_physical(sig):
        return "double"
    if sig.length == 1 and not sig.is_signed:
        return "bool"
    return raw_type(sig)


def number(v) -> str:
    return "" if v is None else str(int(v)) if float(v).is_integer() else repr(float(v))


def stamp_of(msg):
    """The frame's node time for the rolling-counter check: its first signal in
    us or s (NodeTime; NODE_STATUS: Uptime), handed on with its unit in us."""
    for s in msg.signals:
        if s.unit in ("us", "s") and not is_physical(s):
            return s
    sys.exit(f"{msg.name}: no signal in us or s for the rolling-counter check")


def comment(text: str | None) -> str:
    return " ".join((text or "").split()).replace("*/", "* /")


def kinds_of(db) -> list:
    """The frames the bridge receives, in BridgeKind order; checked dense and unique."""
    kinds = {}
    for msg in db.messages:
        receives = any(RECEIVER in s.receivers for s in msg.signals)
        attr = msg.dbc.attributes.get(ATTRIBUTE) if msg.dbc else None
        if receives != (attr is not None):
            sys.exit(f"{msg.name}: a frame the bridge receives has a {ATTRIBUTE} "
                     f"attribute, and only such a frame")
        if attr is None:
            continue
        if attr.value in kinds:
            sys.exit(f"{msg.name}: {ATTRIBUTE} {attr.value} is {kinds[attr.value].name}'s")
        if not any(s.name == "Counter" for s in msg.signals):
            sys.exit(f"{msg.name}: no Counter signal (the bridge follows every kind's counter)")
        stamp_of(msg)
        kinds[attr.value] = msg
    if sorted(kinds) != list(range(len(kinds))):
        sys.exit(f"{ATTRIBUTE} values {sorted(kinds)}: not 0..{len(kinds) - 1}")
    return [kinds[i] for i in range(len(kinds))]


HEADER = "/* Generated at build time by bridge/gen_frame_kinds.py from {dbc}: do not edit. */\n"


def gen_h(kinds, dbc: str) -> str:
    out = [HEADER.format(dbc=dbc), "#ifndef FRAME_KINDS_H", "#define FRAME_KINDS_H", "",
           "#include <stdbool.h>", "#include <stdint.h>", "",
           f"/* The sensor kinds: one per frame the bridge receives, numbered by the",
           f" * frame's {ATTRIBUTE} attribute (the order of the sensor table, the",
           " * stats JSON and the status line). */", "enum frame_kind {"]
    for i, m in enumerate(kinds):
        out.append(f"    FRAME_{m.name} = {i}, /* 0x{m.frame_id:03x} */")
    out += [f"    FRAME_KIND_COUNT = {len(kinds)}", "};", ""]
    for m in kinds:
        out.append(f"/* {m.name} (0x{m.frame_id:03x}): {comment(m.comment)} */")
        out.append(f"struct frame_{m.name.lower()} {{")
        for s in m.signals:
            lo, hi = number(s.minimum), number(s.maximum)
            unit = f" {s.unit}" if s.unit else ""
            out.append(f"    {field_type(s)} {field_name(s)}; /* {s.name} {lo}..{hi}{unit}: "
                       f"{comment(s.comment)} */")
        out += ["};", ""]
    out.append("/* The payloads of struct frame (frames.h), one union member per kind. */")
    out.append("#define FRAME_KIND_PAYLOADS \\")
    out.append(" \\\n".join(f"    struct frame_{m.name.lower()} {m.name.lower()};" for m in kinds))
    out += ["", "/* Unpack the 8 bytes of a frame of the kind into *out (kind and payload)",
            " * and *seq (its Counter and node time; track 0): FRAME_OK, FRAME_MALFORMED",
            " * (the codec refused it) or FRAME_OUT_OF_RANGE (a signal outside its DBC",
            " * range, raw or decoded). */", "struct frame;", "struct frame_seq;"]
    for m in kinds:
        out.append(f"enum frame_result frame_{m.name.lower()}_unpack(const uint8_t data[8], "
                   "struct frame *out,\n    struct frame_seq *seq);")
    out += ["", "#endif /* FRAME_KINDS_H */", ""]
    return "\n".join(out)


def gen_c(kinds, dbc: str) -> str:
    out = [HEADER.format(dbc=dbc), "#include <math.h>", "", '#include "beaconloc_can.h"',
           '#include "frames.h"', ""]
    for m in kinds:
        name = m.name.lower()
        codec = f"{CODEC}_{name}"
        out += [f"enum frame_result frame_{name}_unpack(const uint8_t data[8], struct frame *out,",
                "    struct frame_seq *seq)",
                "{", f"    struct {codec}_t m;",
                f"    if ({codec}_unpack(&m, data, 8) != 0)", "        return FRAME_MALFORMED;"]
        # the raw range of every signal that can leave it; a scaled integer
        # signal's decoded value then lies in its decoded range too
        checks = [f"!{codec}_{snake(s.name)}_is_in_range(m.{snake(s.name)})"
                  for s in m.signals if can_leave_range(s)]
        if checks:
            out.append("    if (" + " ||\n        ".join(checks) + ")")
            out.append("        return FRAME_OUT_OF_RANGE;")
        for s in (s for s in m.signals if is_physical(s)):
            v = snake(s.name)
            out.append(f"    const double {v} = {codec}_{v}_decode(m.{v});")
            if s.is_float:
                out += [f"    if (!isfinite({v}) || !{codec}_{v}_is_in_phys_range({v}))",
                        "        return FRAME_OUT_OF_RANGE;"]
        out += [f"    out->kind = FRAME_{m.name};",
                f"    out->u.{name} = (struct frame_{name}){{"]
        for s in m.signals:
            v = snake(s.name)
            value = v if is_physical(s) else f"m.{v} != 0" if field_type(s) == "bool" else f"m.{v}"
            out.append(f"        .{field_name(s)} = {value},")
        stamp = stamp_of(m)
        tick_us = 1 if stamp.unit == "us" else 1000000
        out += ["    };", f"    *seq = (struct frame_seq){{.counter = m.counter, "
                f".stamp = m.{snake(stamp.name)}, .stamp_tick_us = {tick_us}u, .track = 0}};",
                "    return FRAME_OK;", "}", ""]
    return "\n".join(out)


def gen_list(kinds, dbc: str) -> str:
    out = [HEADER.format(dbc=dbc), '#include "sensors.h"', "",
           "/* Each defined by its kind's own file, bridge/sensor_<kind>.c. */"]
    out += [f"extern const struct sensor_kind sensor_kind_{m.name.lower()};" for m in kinds]
    out += ["", "const struct sensor_kind *const sensor_kinds[FRAME_KIND_COUNT] = {"]
    out += [f"    [FRAME_{m.name}] = &sensor_kind_{m.name.lower()}," for m in kinds]
    out += ["};", ""]
    return "\n".join(out)


def main(argv: list[str]) -> None:
    dbc, outdir = argv[1], Path(argv[2])
    kinds = kinds_of(cantools.database.load_file(dbc))
    outdir.mkdir(parents=True, exist_ok=True)
    for name, text in (("frame_kinds.h", gen_h(kinds, dbc)), ("frame_kinds.c", gen_c(kinds, dbc)),
                       ("sensor_kinds.c", gen_list(kinds, dbc))):
        tmp = outdir / (name + ".tmp")
        tmp.write_text(text)
        tmp.replace(outdir / name)


if __name__ == "__main__":
    main(sys.argv)
