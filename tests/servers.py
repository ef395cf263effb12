"""Real servers for tests, on 127.0.0.1 only: the web app under uvicorn, a folder over plain HTTP."""

from __future__ import annotations

import contextlib
import functools
import http.server
import socket
import threading
import time
from pathlib import Path


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@contextlib.contextmanager
def uvicorn_server(app):
    """Run ``app`` under uvicorn in a thread on a free port; yields (host, port)."""
    import uvicorn

    port = free_port()
    srv = uvicorn.Server(uvicorn.Config(app, host="127.0.0.1", port=port, log_level="warning"))
    thread = threading.Thread(target=srv.run, daemon=True)
    thread.start()
    deadline = time.monotonic() + 20
    while not srv.started and time.monotonic() < deadline and thread.is_alive():
        time.sleep(0.05)
    assert srv.started, "the server did not start within 20 s"
    try:
        yield "127.0.0.1", port
    finally:
        srv.should_exit = True
        thread.join(timeout=10)
    assert not thread.is_alive(), "the server did not stop within 10 s"


class QuietHandler(http.server.SimpleHTTPRequestHandler):
    def log_message(self, *args):
        pass


@contextlib.contextmanager
def http_folder(directory, handler=QuietHandler):
    """``directory`` over plain HTTP (the way an Internet radio relays a file); yields the base URL."""
    httpd = http.server.ThreadingHTTPServer(("127.0.0.1", 0), functools.partial(handler, directory=str(directory)))
    thread = threading.Thread(target=httpd.serve_forever, kwargs={"poll_interval": 0.1}, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{httpd.server_address[1]}"
    finally:
        httpd.shutdown()
        httpd.server_close()
        thread.join(timeout=10)


def radio(payload: bytes, rate: float, *, stall_at: int | None = None, stall_s: float = 0.0, resume: bool = True,
          content_type: str = "audio/mpeg"):
    """A handler class for an Internet radio: ``payload`` sent at ``rate`` bytes/s with no length.

    Once ``stall_at`` bytes are out it sends nothing for ``stall_s`` s (connections stay open), then goes
    on (``resume``) or goes off the air (closes, and later connections get 503). A new connection gets
    the broadcast from where it is now (a live stream has no past).
    """

    class Radio(QuietHandler):
        sent = 0
        stall_until: float | None = None

        def do_GET(self):
            cls = type(self)
            if cls.sent >= len(payload) or self._off_air():
                self.send_error(503)
                return
            self.send_response(200)
            self.send_header("Content-Type", content_type)
            self.end_headers()
            step = max(int(rate / 10), 1)
            try:
                while cls.sent < len(payload):
                    if stall_at is not None and cls.sent >= stall_at and cls.stall_until is None:
                        cls.stall_until = time.monotonic() + stall_s
                    if cls.stall_until is not None and time.monotonic() < cls.stall_until:
                        time.sleep(0.1)  # silent, the connection open
                        continue
                    if self._off_air():
                        return
                    end = min(cls.sent + step, len(payload))
                    if stall_at is not None and cls.stall_until is None:
                        end = min(end, max(stall_at, cls.sent + 1))
                    self.wfile.write(payload[cls.sent:end])
                    self.wfile.flush()
                    cls.sent = end
                    time.sleep(0.1)
            except OSError:  # the listener went away
                pass

        def _off_air(self) -> bool:
            return not resume and self.stall_until is not None and time.monotonic() >= self.stall_until

    return Radio


def range_ignoring(cut: float = 0.4):
    """A handler class serving files with their length but ignoring HTTP Range, cutting every connection
    off after ``cut`` of the file (a reconnect that asks to resume gets the file from its start again)."""

    class RangeIgnoring(QuietHandler):
        requests = 0

        def do_GET(self):
            type(self).requests += 1
            data = (Path(self.directory) / self.path.lstrip("/")).read_bytes()
            self.send_response(200)
            self.send_header("Content-Length", str(len(data)))
            self.end_headers()
            self.wfile.write(data[:int(len(data) * cut)])
            self.wfile.flush()
            self.connection.shutdown(socket.SHUT_RDWR)

    return RangeIgnoring


def silent(hold_s: float = 60.0):
    """A handler class that answers 200 with an audio type and then sends nothing for ``hold_s`` s."""

    class Silent(QuietHandler):
        def do_GET(self):
            self.send_response(200)
            self.send_header("Content-Type", "audio/mpeg")
            self.end_headers()
            self.wfile.flush()
            time.sleep(hold_s)

    return Silent
