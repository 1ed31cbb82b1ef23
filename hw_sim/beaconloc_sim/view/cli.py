"""beaconloc-view: a live map of the bridge's MAVLink stream in the browser
(docs/view.md)."""
from __future__ import annotations

import argparse
import sys
import threading
import time
from pathlib import Path

from ..inifile import ConfigError
from ..resources import builtin_site_path
from ..scenario import is_team_scenario, load_scenario, resolve
from ..site import load_site
from ..team_scenario import load_team_scenario
from .server import make_server
from .source import Receiver
from .state import ViewState


def load_place(site: str | None, scenario: str | None):
    """(site, obstacles) from a site file (a path or a built-in site name) or from a
    scenario (a path or a built-in name: its site and its [obstacles]). The simulator's
    loaders, so the viewer reads exactly what the simulator and the bridge read."""
    if scenario:
        scn = load_team_scenario(scenario) if is_team_scenario(scenario) else \
            load_scenario(resolve(scenario))
        return scn.site, scn.obstacles_m
    path = Path(site)
    if not path.exists() and "/" not in site and not site.endswith(".ini"):
        path = builtin_site_path(site)
    # team=True: a team's site may have no fixed beacons (the robots range each other)
    return load_site(path, team=True), None


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="beaconloc-view", description=__doc__)
    place = ap.add_mutually_exclusive_group(required=True)
    place.add_argument("--site", help="site file (path or built-in name, e.g. kleeman-lab)")
    place.add_argument("--scenario", help="scenario (path or built-in name): its site and obstacles")
    src = ap.add_mutually_exclusive_group()
    src.add_argument("--mavlink", default=None,
                     help="pymavlink endpoint to read (default udpin:127.0.0.1:14550, where the "
                          "bridge sends by default); udpout:HOST:PORT / tcp:HOST:PORT for a router")
    src.add_argument("--follow", metavar="FILE",
                     help="read a growing file of raw MAVLink frames instead (make demo)")
    ap.add_argument("--compid", type=int, default=197, help="the bridge's component id (197)")
    ap.add_argument("--bind", default="127.0.0.1", help="HTTP address (127.0.0.1)")
    ap.add_argument("--port", type=int, default=8765, help="HTTP port (8765; 0: any free one)")
    ap.add_argument("--rate", type=float, default=20.0, help="page updates per second (20)")
    ap.add_argument("--url-file", help="write the page's URL into this file once serving")
    ap.add_argument("--exit-idle", type=float, default=None, metavar="S",
                    help="exit after S seconds without a message (default: run until stopped)")
    return ap


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if not 1.0 <= args.rate <= 100.0:
        print("beaconloc-view: --rate must be in [1, 100]", file=sys.stderr)
        return 64
    try:
        site, obstacles = load_place(args.site, args.scenario)
    except (ConfigError, FileNotFoundError, ValueError) as e:
        print(f"beaconloc-view: {e}", file=sys.stderr)
        return 78
    state = ViewState(site, obstacles, compid=args.compid)
    try:
        server = make_server(state, args.bind, args.port, args.rate)
    except OSError as e:
        print(f"beaconloc-view: cannot serve on {args.bind}:{args.port}: {e.strerror}",
              file=sys.stderr)
        return 69
    host, port = server.server_address[:2]
    url = f"http://{'127.0.0.1' if host in ('0.0.0.0', '') else host}:{port}/"
    source = args.follow or args.mavlink or "udpin:127.0.0.1:14550"
    try:
        recv = Receiver(state.ingest, follow=args.follow,
                        endpoint=None if args.follow else source).start()
    except OSError as e:
        print(f"beaconloc-view: cannot open {source}: {e}", file=sys.stderr)
        return 69
    threading.Thread(target=server.serve_forever, name="http", daemon=True).start()
    print(f"beaconloc-view: {site.name} from {source}: {url}", flush=True)
    if args.url_file:
        Path(args.url_file).write_text(url + "\n")
    try:
        while args.exit_idle is None or recv.idle_s() < args.exit_idle:
            time.sleep(0.2)
        print(f"beaconloc-view: no message for {args.exit_idle:g} s, exiting", flush=True)
    except KeyboardInterrupt:
        pass
    finally:
        server.shutdown()
        recv.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
