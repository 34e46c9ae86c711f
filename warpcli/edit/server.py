"""The editor's local web server: the page, its assets and the session's calls, on 127.0.0.1 behind a token.

What it lets through, and why (a server on a user's machine is reachable by
every web page the user opens, through the browser):

- it listens on 127.0.0.1 only;
- every request carries the session's random token (`secrets.token_urlsafe`),
  in the URL's ``token`` (the page, the image, the assets) or the
  ``X-Warp-Token`` header (the calls), compared in constant time;
- the Host header must name this server (``127.0.0.1:PORT`` or
  ``localhost:PORT``): a DNS-rebinding page reaches it under its own name
  and is refused;
- an Origin header, when present, must be this server's own, and a
  cross-site ``Sec-Fetch-Site`` is refused: no other site's page can call it;
- it serves a fixed list of paths: the page, its assets (read from the
  package, by name, from a fixed list) and the image's preview, never a
  path taken from the request (a polygon file loaded on the page arrives
  as its text: the server reads nothing for it);
- bodies are JSON of at most `MAX_BODY` bytes, with a Content-Length, read
  only once every header check passed;
- it writes only through `EditSession.save` and `EditSession.export`: the
  paths of the command line, or a plain file name in the image's directory.
"""

from __future__ import annotations

import hmac
import json
import logging
import secrets
import selectors
import socket
import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from importlib import resources
from urllib.parse import parse_qs, urlsplit

from ..errors import WarpError
from .session import EditSession

__all__ = ["ASSETS", "MAX_BODY", "EditServer"]

#: Largest request body accepted, in bytes.
MAX_BODY = 1 << 20
#: The page's assets by URL path: file name in ``warpcli/edit/static`` and content type.
ASSETS = {
    "/": ("index.html", "text/html; charset=utf-8"),
    "/static/editor.js": ("editor.js", "text/javascript; charset=utf-8"),
    "/static/editor.css": ("editor.css", "text/css; charset=utf-8"),
}
#: Headers of every response: nothing is cached, framed, sniffed or sent elsewhere.
SECURITY_HEADERS = {
    "Cache-Control": "no-store",
    "X-Content-Type-Options": "nosniff",
    "X-Frame-Options": "DENY",
    "Referrer-Policy": "no-referrer",
    "Content-Security-Policy": "default-src 'self'; img-src 'self' blob:; style-src 'self'; script-src 'self'; "
    "connect-src 'self'; frame-ancestors 'none'; base-uri 'none'; form-action 'none'",
}

log = logging.getLogger("warpcli")


class EditServer:
    """The editor's server for one session, on 127.0.0.1 and a free port (or ``port``).

    Parameters
    ----------
    session : EditSession
    port : int
        0: any free port.
    token : str or None
        The token every request must carry; None: a new random one.

    Examples
    --------
    ``server.url`` is what the browser opens; ``server.serve_forever()``
    serves until ``server.shutdown()``.
    """

    def __init__(self, session: EditSession, port: int = 0, token: str | None = None) -> None:
        self.session = session
        self.token = token or secrets.token_urlsafe(32)
        self.httpd = ThreadingHTTPServer(("127.0.0.1", port), _handler(self))
        self.httpd.daemon_threads = True
        self.port = self.httpd.server_address[1]
        self.hosts = {f"127.0.0.1:{self.port}", f"localhost:{self.port}"}
        self.origins = {f"http://{h}" for h in self.hosts}
        self._assets = {path: _read_asset(name) for path, (name, _) in ASSETS.items()}
        # One call of the session at a time: the page sends one, and a save
        # must not interleave with an export.
        self.calls = threading.Lock()
        # `shutdown` wakes the serving loop through this pair of sockets: the loop sleeps in
        # select() until a connection or the wake-up, instead of waking to poll a flag.
        self._wake_read, self._wake_write = socket.socketpair()
        self._state = threading.Lock()
        self._stopping = False
        self._idle = threading.Event()  # set while no loop serves
        self._idle.set()

    @property
    def url(self) -> str:
        """The page's address, with the token."""
        return f"http://127.0.0.1:{self.port}/?token={self.token}"

    def serve_forever(self) -> None:
        """Serve until `shutdown` (at once if it was already called)."""
        with self._state:
            if self._stopping:
                return
            self._idle.clear()
        try:
            with selectors.DefaultSelector() as selector:
                selector.register(self.httpd, selectors.EVENT_READ)
                selector.register(self._wake_read, selectors.EVENT_READ)
                self.httpd.timeout = 0  # handle_request() then never blocks on a connection gone meanwhile
                while True:
                    ready = [key.fileobj for key, _ in selector.select()]
                    if self._wake_read in ready:
                        return
                    self.httpd.handle_request()
        finally:
            self._idle.set()

    def start(self) -> threading.Thread:
        """Serve on a daemon thread; return it."""
        thread = threading.Thread(target=self.serve_forever, name="warp-edit-server", daemon=True)
        thread.start()
        return thread

    def shutdown(self) -> None:
        """Stop serving, wait for the serving loop to end and close the sockets; a second call does nothing."""
        with self._state:
            if self._stopping:
                return
            self._stopping = True
        self._wake_write.send(b"\0")
        self._idle.wait()
        self.httpd.server_close()
        self._wake_read.close()
        self._wake_write.close()

    def asset(self, path: str) -> bytes:
        """The asset at URL ``path``; the page with its token filled in."""
        data = self._assets[path]
        return data.replace(b"{{TOKEN}}", self.token.encode()) if path == "/" else data


def _read_asset(name: str) -> bytes:
    return resources.files(__package__).joinpath("static", name).read_bytes()  # the package's data, not a module


def _handler(server: EditServer) -> type[BaseHTTPRequestHandler]:
    class Handler(BaseHTTPRequestHandler):
        server_version = "warp-edit"
        sys_version = ""
        protocol_version = "HTTP/1.1"
        # The headers and the body go out as two writes: with Nagle's algorithm the second waits
        # for the browser's delayed ACK of the first (up to 40 ms a preview).
        disable_nagle_algorithm = True

        def log_message(self, format: str, *args) -> None:  # noqa: A002 - the base class's name
            log.debug("edit: " + format, *args)

        # --- refusing ---------------------------------------------------------------

        def refused(self) -> str | None:
            """Why this request is refused (a status line's reason), or None: the headers and token are checked here."""
            host = self.headers.get("Host", "")
            if host not in server.hosts:
                return "421 wrong Host"
            origin = self.headers.get("Origin")
            if origin is not None and origin not in server.origins:
                return "403 foreign Origin"
            if self.headers.get("Sec-Fetch-Site", "same-origin") not in ("same-origin", "none"):
                return "403 cross-site request"
            query = parse_qs(urlsplit(self.path).query)
            given = self.headers.get("X-Warp-Token") or (query.get("token") or [""])[0]
            if not hmac.compare_digest(given.encode(), server.token.encode()):
                return "403 wrong token"
            return None

        def send(self, status: int, body: bytes, kind: str, reason: str | None = None) -> None:
            self.send_response(status, reason)
            self.send_header("Content-Type", kind)
            self.send_header("Content-Length", str(len(body)))
            for key, value in SECURITY_HEADERS.items():
                self.send_header(key, value)
            self.end_headers()
            if self.command != "HEAD":
                self.wfile.write(body)

        def fail(self, why: str) -> None:
            status, _, reason = why.partition(" ")
            self.close_connection = True
            self.send(int(status), json.dumps({"error": reason}).encode(), "application/json", reason)

        # --- serving --------------------------------------------------------------------

        def do_GET(self) -> None:  # noqa: N802 - the base class's name
            why = self.refused()
            if why is not None:
                return self.fail(why)
            path = urlsplit(self.path).path
            if path in ASSETS:
                return self.send(200, server.asset(path), ASSETS[path][1])
            if path == "/image.png":
                return self.send(200, server.session.png, "image/png")
            if path == "/api/state":
                return self.send(200, json.dumps(server.session.state()).encode(), "application/json")
            return self.fail("404 not found")

        do_HEAD = do_GET

        def do_POST(self) -> None:  # noqa: N802
            why = self.refused()
            if why is not None:
                return self.fail(why)
            path = urlsplit(self.path).path
            calls = {
                "/api/preview": None, "/api/load": server.session.load, "/api/save": server.session.save,
                "/api/export": server.session.export,
            }  # fmt: skip
            if path not in calls:
                return self.fail("404 not found")
            if "chunked" in self.headers.get("Transfer-Encoding", "").lower():
                return self.fail("411 length required")
            try:
                length = int(self.headers.get("Content-Length", ""))
            except ValueError:
                return self.fail("411 length required")
            if length < 0 or length > MAX_BODY:
                return self.fail("413 body too large")
            if self.headers.get("Content-Type", "").split(";")[0].strip() != "application/json":
                return self.fail("415 JSON only")
            body = self.rfile.read(length)
            try:
                doc = json.loads(body)
            except (ValueError, RecursionError):
                return self.fail("400 not JSON")
            if not isinstance(doc, dict):
                return self.fail("400 not a JSON object")
            with server.calls:
                if path == "/api/preview":
                    return self.send(200, server.session.preview_map(doc), "application/octet-stream")
                try:
                    result = dict(calls[path](doc), ok=True)
                except WarpError as err:
                    result = {"ok": False, "error": str(err)}
            return self.send(200, json.dumps(result).encode(), "application/json")

        def do_PUT(self) -> None:  # noqa: N802
            self.fail("405 method not allowed")

        do_DELETE = do_PATCH = do_OPTIONS = do_PUT

    return Handler
