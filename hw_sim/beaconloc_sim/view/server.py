"""beaconloc-view's HTTP server (stdlib http.server, one thread per connection):

  /            the page (page.html: SVG map, drawn by its own script)
  /site.json   the site: room, obstacles, beacons of every kind
  /state.json  one snapshot of the state (whole trails)
  /events      server-sent events: a snapshot every 1/rate s, trails as increments
"""
from __future__ import annotations

import json
import time
from http import HTTPStatus
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from importlib import resources

from .state import ViewState

PAGE = resources.files(__package__).joinpath("page.html").read_bytes()


def make_server(state: ViewState, host: str, port: int, rate_hz: float) -> ThreadingHTTPServer:
    period_s = 1.0 / rate_hz

    class Handler(BaseHTTPRequestHandler):
        server_version = "beaconloc-view"

        def log_message(self, fmt, *args):  # quiet: one line per request is noise here
            pass

        def _send(self, body: bytes, ctype: str) -> None:
            self.send_response(HTTPStatus.OK)
            self.send_header("Content-Type", ctype)
            self.send_header("Content-Length", str(len(body)))
            self.send_header("Cache-Control", "no-store")
            self.end_headers()
            self.wfile.write(body)

        def do_GET(self):  # noqa: N802 (http.server's name)
            path = self.path.split("?", 1)[0]
            if path in ("/", "/index.html"):
                self._send(PAGE, "text/html; charset=utf-8")
            elif path == "/site.json":
                self._send(json.dumps(state.site_json()).encode(), "application/json")
            elif path == "/state.json":
                self._send(json.dumps(state.snapshot({})).encode(), "application/json")
            elif path == "/events":
                self._events()
            else:
                self.send_error(HTTPStatus.NOT_FOUND)

        def _events(self) -> None:
            self.send_response(HTTPStatus.OK)
            self.send_header("Content-Type", "text/event-stream")
            self.send_header("Cache-Control", "no-store")
            self.end_headers()
            cursors: dict[int, int] = {}
            next_s = time.monotonic()
            try:
                while True:
                    body = json.dumps(state.snapshot(cursors), separators=(",", ":"))
                    self.wfile.write(f"data: {body}\n\n".encode())
                    self.wfile.flush()
                    next_s += period_s
                    time.sleep(max(0.0, next_s - time.monotonic()))
                    next_s = max(next_s, time.monotonic() - period_s)
            except (BrokenPipeError, ConnectionResetError):
                return

    server = ThreadingHTTPServer((host, port), Handler)
    server.daemon_threads = True
    return server
