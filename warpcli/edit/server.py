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
  cross-site ``Sec-Fetch-Site`` is refused: no other site's page can call it
  (but a tab may open the page itself, ``/`` with the token, from the local
  file the browser is started on: `warpcli.edit.redirect_page`);
- it serves a fixed list of paths: the page, its assets (read from the
  package, by name, from a fixed list) and the image's preview, never a
  path taken from the request (a polygon file loaded on the page arrives
  as its text: the server reads nothing for it);
- bodies are JSON of at most `MAX_BODY` bytes, with a Content-Length, read
  only once every header check passed, and parsed one at a time, once the
  session is free (`EditServer.calls`): a preview asked for while another
  call runs is answered 503 at once, its body unparsed, and the page asks
  again; a save or an export waits its turn;
- every connection has `REQUEST_TIMEOUT` seconds for a request to arrive
  whole (a connection that sends nothing, or a byte at a time, is closed),
  at most `MAX_CONNECTIONS` are served at once (beyond them, the one that
  has waited longest for its request makes room, else the new one is closed),
  and out of file descriptors the server closes such a waiting connection
  or pauses accepting for `ACCEPT_BACKOFF` seconds, instead of spinning;
- an unexpected error in a request (a bug, `MemoryError`) is answered 500
  with a JSON error and logged as one line; the server goes on serving;
- it writes only through `EditSession.save` and `EditSession.export`: the
  paths of the command line, or a plain file name in the image's directory,
  never an input of the session.
"""

from __future__ import annotations

import contextlib
import errno
import hmac
import io
import json
import logging
import math
import secrets
import selectors
import socket
import sys
import threading
import time
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from importlib import resources
from urllib.parse import parse_qs, urlsplit

from ..errors import WarpError
from .session import EditSession

__all__ = ["ACCEPT_BACKOFF", "ASSETS", "MAX_BODY", "MAX_CONNECTIONS", "REQUEST_TIMEOUT", "EditServer"]

#: Largest request body accepted, in bytes.
MAX_BODY = 1 << 20
#: Seconds a request has to arrive whole (its line, headers and body) from when the server starts
#: reading it, and a response to be taken: then the connection is closed. A keep-alive connection
#: that sends nothing more is closed after as long.
REQUEST_TIMEOUT = 30.0
#: Connections served at once (a browser opens six to a server); beyond them the one that has waited
#: longest for its request makes room, else the new one is closed.
MAX_CONNECTIONS = 32
#: Connections the system queues before the server accepts them (``listen``'s backlog).
LISTEN_BACKLOG = 128
# Seconds a new connection waits for the thread of the connection closed to make room for it to end.
_ROOM_WAIT = 1.0
# Seconds the accept loop waits, out of file descriptors, after closing a connection to free one.
_ROOM_PAUSE = 0.005
# Seconds between two warnings that the server is out of file descriptors.
_WARN_EVERY = 60.0
#: Seconds the server stops accepting after an accept failed for want of file descriptors.
ACCEPT_BACKOFF = 0.1
# accept() errors that mean "no file descriptor (or memory) for now": the connection stays queued.
_OUT_OF_FILES = frozenset({errno.EMFILE, errno.ENFILE, errno.ENOBUFS, errno.ENOMEM})
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
        self.httpd = _Server(("127.0.0.1", port), _handler(self), MAX_CONNECTIONS)
        self.port = self.httpd.server_address[1]
        self.hosts = {f"127.0.0.1:{self.port}", f"localhost:{self.port}"}
        self.origins = {f"http://{h}" for h in self.hosts}
        self._assets = {path: _read_asset(name) for path, (name, _) in ASSETS.items()}
        # One call of the session at a time: the page sends one, and a save must not interleave
        # with an export. A preview does not wait for it (503, the page asks again); the others do.
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
            with selectors.DefaultSelector() as selector, selectors.DefaultSelector() as wake_only:
                selector.register(self.httpd, selectors.EVENT_READ)
                selector.register(self._wake_read, selectors.EVENT_READ)
                wake_only.register(self._wake_read, selectors.EVENT_READ)
                self.httpd.timeout = 0  # handle_request() then never blocks on a connection gone meanwhile
                warned = -math.inf  # when "out of file descriptors" was last logged
                while True:
                    ready = [key.fileobj for key, _ in selector.select()]
                    if self._wake_read in ready:
                        return
                    self.httpd.handle_request()
                    if not self.httpd.accept_failed:
                        continue
                    # The connection stays queued, so select() would report it again at once: a
                    # busy loop for as long as the process is out of descriptors. Close the
                    # connection idle longest (its thread gives its descriptor back in a moment),
                    # else pause; shutdown still wakes either wait.
                    self.httpd.accept_failed = False
                    if time.monotonic() - warned > _WARN_EVERY:
                        log.warning("edit: out of file descriptors: new connections wait")
                        warned = time.monotonic()
                    if wake_only.select(_ROOM_PAUSE if self.httpd.make_room() else ACCEPT_BACKOFF):
                        return
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


class _Server(ThreadingHTTPServer):
    """The standard threading server, bounded: at most ``max_connections`` handler threads, a deeper
    backlog, and an accept that says when it failed for want of file descriptors
    (`EditServer.serve_forever` then pauses).

    With every thread taken, the connection that has waited longest for its
    request (idle, or trickling it in) is closed to make room for the new
    one: idle connections cannot lock the page out for `REQUEST_TIMEOUT`.
    When every thread is in a call (none is waiting for a request), the new
    connection is closed at once.
    """

    daemon_threads = True
    request_queue_size = LISTEN_BACKLOG

    def __init__(self, address: tuple[str, int], handler: type[BaseHTTPRequestHandler], max_connections: int) -> None:
        self.slots = threading.BoundedSemaphore(max_connections)
        self.accept_failed = False
        self._waiting: dict[socket.socket, float] = {}  # connection -> since when it waits for (part of) a request
        self._waiting_lock = threading.Lock()
        super().__init__(address, handler)

    def waiting(self, connection: socket.socket) -> None:
        """``connection`` waits for a request (or its body) from now: it may be closed to make room."""
        with self._waiting_lock:
            self._waiting[connection] = time.monotonic()

    def arrived(self, connection: socket.socket) -> bool:
        """What ``connection`` waited for has arrived: it is no longer closed to make room. False if it was closed."""
        with self._waiting_lock:
            return self._waiting.pop(connection, None) is not None

    def make_room(self) -> bool:
        """Close the connection that has waited longest for its request; False if none waits."""
        with self._waiting_lock:
            if not self._waiting:
                return False
            connection = min(self._waiting, key=self._waiting.__getitem__)
            del self._waiting[connection]
        with contextlib.suppress(OSError):
            connection.shutdown(socket.SHUT_RDWR)  # its thread's read ends at once, and the thread with it
        return True

    def get_request(self):
        try:
            return super().get_request()
        except OSError as err:
            if err.errno in _OUT_OF_FILES:
                self.accept_failed = True
            raise

    def process_request(self, request, client_address) -> None:
        if not self.slots.acquire(blocking=False) and not (
            self.make_room() and self.slots.acquire(timeout=_ROOM_WAIT)
        ):
            log.debug("edit: %d connections in calls already: one more closed", MAX_CONNECTIONS)
            self.shutdown_request(request)
            return
        try:
            super().process_request(request, client_address)
        except BaseException:  # no thread started: its slot is free again
            self.slots.release()
            raise

    def process_request_thread(self, request, client_address) -> None:
        try:
            super().process_request_thread(request, client_address)
        finally:
            self.arrived(request)
            self.slots.release()

    def handle_error(self, request, client_address) -> None:
        # The standard server prints a traceback on stderr; a connection's failure outside a request's
        # handler (the browser went away) is one line, and only a real failure is an error.
        err = sys.exc_info()[1]
        if isinstance(err, (ConnectionError, TimeoutError)):
            log.debug("edit: connection closed: %s", _summary(err))
        else:
            log.error("edit: a connection failed: %s", _summary(err))


class _DeadlineReader(io.RawIOBase):
    """A connection's reads, each allowed only what is left of its request's time (``handler.deadline``).

    A timeout per read (``socket.settimeout`` alone) would let a request
    trickle in a byte every few seconds and hold its connection for ever;
    here the whole request must arrive by the deadline, else `TimeoutError`
    (the standard handler then closes the connection).
    """

    def __init__(self, handler: BaseHTTPRequestHandler) -> None:
        self._handler = handler

    def readable(self) -> bool:
        return True

    def readinto(self, buffer) -> int:
        left = self._handler.deadline - time.monotonic()
        if left <= 0:
            raise TimeoutError("the request did not arrive in time")
        self._handler.connection.settimeout(left)
        return self._handler.connection.recv_into(buffer)


def _summary(err: BaseException) -> str:
    """An exception as one line: its type and message."""
    text = " ".join(str(err).split())
    return f"{type(err).__name__}: {text}"[:300] if text else type(err).__name__


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

        def setup(self) -> None:
            super().setup()
            self.deadline = time.monotonic() + REQUEST_TIMEOUT
            self.sent = False  # whether this request's response has begun
            self.rfile.close()  # the socket's own reader: reads go through the deadline instead
            self.rfile = io.BufferedReader(_DeadlineReader(self))

        def handle_one_request(self) -> None:
            # The next request, whole, within REQUEST_TIMEOUT of when the server starts waiting for it.
            self.deadline = time.monotonic() + REQUEST_TIMEOUT
            self.sent = False
            self.server.waiting(self.connection)
            super().handle_one_request()

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
            if self.headers.get("Sec-Fetch-Site", "same-origin") not in ("same-origin", "none") and not self.opening():
                return "403 cross-site request"
            query = parse_qs(urlsplit(self.path).query)
            given = self.headers.get("X-Warp-Token") or (query.get("token") or [""])[0]
            if not hmac.compare_digest(given.encode(), server.token.encode()):
                return "403 wrong token"
            return None

        def opening(self) -> bool:
            """Whether this is the browser opening the page itself, in a tab: a top-level navigation to ``/``.

            The browser is opened on a local file that sends it on to the page
            (`warpcli.edit.redirect_page`), and a navigation from a ``file:``
            page is cross-site. Letting that one through calls nothing: the
            page is the token's to load (as from a link in the terminal,
            ``Sec-Fetch-Site: none``), never in a frame, unreadable by another site.
            """
            return (
                self.command in ("GET", "HEAD") and urlsplit(self.path).path == "/"
                and self.headers.get("Sec-Fetch-Mode") == "navigate" and self.headers.get("Sec-Fetch-Dest") == "document"
            )  # fmt: skip

        def send(self, status: int, body: bytes, kind: str, reason: str | None = None) -> None:
            self.connection.settimeout(REQUEST_TIMEOUT)  # for the browser to take the response
            self.sent = True
            self.send_response(status, reason)
            self.send_header("Content-Type", kind)
            self.send_header("Content-Length", str(len(body)))
            for key, value in SECURITY_HEADERS.items():
                self.send_header(key, value)
            self.end_headers()
            if self.command != "HEAD":
                self.wfile.write(body)

        def fail(self, why: str, error: str | None = None, close: bool = True) -> None:
            """Answer ``why`` ("STATUS reason") with ``{"error": error or reason}``; ``close``: then close the connection."""
            status, _, reason = why.partition(" ")
            self.close_connection = self.close_connection or close
            self.send(int(status), json.dumps({"error": error or reason}).encode(), "application/json", reason)

        def guarded(self, serve) -> None:
            """``serve()``; an unexpected error is answered 500 (a JSON error) and logged as one line.

            Any exception, not only `WarpError`: whatever one request meets (a
            bug, `MemoryError`), the browser gets an answer it can show and
            the server goes on serving the others. The traceback is logged at
            debug level (``warp -vv edit``), for a bug report.
            """
            if not self.server.arrived(self.connection):  # closed to make room meanwhile
                self.close_connection = True
                return
            try:
                serve()
            except TimeoutError:
                raise  # the standard handler closes the connection
            except ConnectionError:
                self.close_connection = True  # the browser went away: nobody to answer
            except Exception as err:  # whatever it is: see the docstring
                what = f"{self.command} {urlsplit(self.path).path}"
                log.error("edit: %s failed: %s", what, _summary(err))
                log.debug("edit: %s failed", what, exc_info=True)
                self.close_connection = True
                if not self.sent:  # else the response is cut short: the connection's end says so
                    with contextlib.suppress(OSError):
                        self.fail("500 internal error", f"internal error ({_summary(err)}); the server goes on")

        # --- serving --------------------------------------------------------------------

        def do_GET(self) -> None:  # noqa: N802 - the base class's name
            self.guarded(self.serve_get)

        do_HEAD = do_GET

        def do_POST(self) -> None:  # noqa: N802
            self.guarded(self.serve_post)

        def serve_get(self) -> None:
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

        def serve_post(self) -> None:
            why = self.refused()
            if why is not None:
                return self.fail(why)
            path = urlsplit(self.path).path
            if path not in ("/api/preview", "/api/load", "/api/save", "/api/export"):
                return self.fail("404 not found")
            if "chunked" in self.headers.get("Transfer-Encoding", "").lower():
                return self.fail("411 length required")
            given = self.headers.get("Content-Length", "").strip()
            if not given:
                return self.fail("411 length required")
            # Digits alone (RFC 9110): int() would also take "+284", "2_84" or " -1".
            if not (given.isascii() and given.isdigit()):
                return self.fail("400 bad request", "Content-Length must be digits")
            length = int(given) if len(given) <= 12 else MAX_BODY + 1
            if length > MAX_BODY:
                return self.fail("413 body too large")
            if self.headers.get("Content-Type", "").split(";")[0].strip() != "application/json":
                return self.fail("415 JSON only")
            # The body is read now, within the request's time, but parsed only once the session is
            # free: requests waiting for it hold their bytes (MAX_CONNECTIONS at most), not a parsed
            # document each (some 24 times bigger). A preview does not wait (behind a long one the
            # page's next ones would queue): it is answered 503 at once and the page asks again.
            self.server.waiting(self.connection)
            body = self.rfile.read(length)
            if not self.server.arrived(self.connection):
                self.close_connection = True
                return None
            if path == "/api/preview":
                if not server.calls.acquire(blocking=False):
                    return self.fail("503 busy", "busy: another preview or a save is running; ask again", close=False)
            else:
                server.calls.acquire()
            try:
                answer = self.call(path, body)
            finally:
                server.calls.release()
            self.send(*answer)

        def call(self, path: str, body: bytes) -> tuple[int, bytes, str]:
            """The call at ``path`` with ``body`` (the session's lock held): the response's status, body and type."""
            try:
                doc = json.loads(body)
            except (ValueError, RecursionError):
                return 400, b'{"error": "not JSON"}', "application/json"
            if not isinstance(doc, dict):
                return 400, b'{"error": "not a JSON object"}', "application/json"
            session = server.session
            if path == "/api/preview":
                return 200, session.preview_map(doc), "application/octet-stream"
            calls = {"/api/load": session.load, "/api/save": session.save, "/api/export": session.export}
            try:
                result = dict(calls[path](doc), ok=True)
            except WarpError as err:
                result = {"ok": False, "error": str(err)}
            return 200, json.dumps(result).encode(), "application/json"

        def do_PUT(self) -> None:  # noqa: N802
            self.fail("405 method not allowed")

        do_DELETE = do_PATCH = do_OPTIONS = do_TRACE = do_CONNECT = do_PUT

        def send_error(self, code: int, message: str | None = None, explain: str | None = None) -> None:
            """The standard library's own errors (a bad request line, a method it has no ``do_`` for,
            a header too long) as every other answer: JSON, with the security headers, then closed."""
            reason = message or self.responses.get(code, ("error",))[0]
            self.close_connection = True
            try:
                self.send(code, json.dumps({"error": reason}).encode(), "application/json", reason)
            except OSError:
                pass

    return Handler
