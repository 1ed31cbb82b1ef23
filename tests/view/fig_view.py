"""make fig-view: docs/img/view.png, the page after a paced replay of beacon-outage (46 s
at 4x: beacons 2 and 5 lost, the trail of the first lap).

    fig_view.py --out PNG
"""
from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bridge"))
from browser import Browser  # noqa: E402
from bridge_helpers import free_udp_port, run_sim  # noqa: E402
from view_rig import start_replay, start_view, stop  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", required=True)
    ap.add_argument("--scenario", default="beacon-outage")
    ap.add_argument("--duration", type=float, default=46)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        log, _ = run_sim(tmp, args.scenario, args.duration)
        port = free_udp_port()
        view, url = start_view(tmp, args.scenario, port)
        browser = None
        try:
            browser = Browser()
            browser.goto(url)
            bridge = start_replay(tmp, log, 4, [port])
            rc = bridge.wait(timeout=300)
            if rc != 0:
                print(f"fig-view: bridge exit {rc}: {(tmp / 'bridge.out').read_text()[-2000:]}")
                return 1
            time.sleep(1.0)
            browser.screenshot(args.out)
        finally:
            if browser is not None:
                browser.close()
            stop(view)
    print(f"fig-view: {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
