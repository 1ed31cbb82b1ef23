"""One CAN frame out and back on a SocketCAN interface (python-can).

Usage: vcan_roundtrip.py IFACE. Exits 0 and prints the frame when a second
socket on IFACE receives exactly the frame the first one sent; non-zero with
the reason otherwise. The integration runner calls it before any test so a
missing bus is reported as such, not as a pile of test failures.
"""
import sys

import can


def main() -> int:
    iface = sys.argv[1] if len(sys.argv) > 1 else "vcan0"
    sent = can.Message(arbitration_id=0x7FF, data=bytes(range(8)), is_extended_id=False)
    try:
        with can.Bus(interface="socketcan", channel=iface) as tx, \
             can.Bus(interface="socketcan", channel=iface) as rx:
            tx.send(sent)
            got = rx.recv(timeout=5.0)
    except (OSError, can.CanError) as exc:
        print(f"vcan round trip on {iface}: {exc}")
        return 1
    if got is None:
        print(f"vcan round trip on {iface}: nothing received within 5 s")
        return 1
    if got.arbitration_id != sent.arbitration_id or bytes(got.data) != bytes(sent.data):
        print(f"vcan round trip on {iface}: sent {sent} but received {got}")
        return 1
    print(f"vcan round trip on {iface}: ok: {got}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
