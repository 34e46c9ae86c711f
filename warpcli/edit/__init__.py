"""``warp edit``: a cage editor in the browser whose preview is the map itself, served on 127.0.0.1.

- `preview`: the image at preview size and the map at preview density, as a textured mesh;
- `session`: the image, the polygons, the options, saving and exporting through the pipeline;
- `server`: the HTTP server (standard library) and its checks: token, Host, Origin, sizes;
- ``static/``: the page (HTML, CSS, JavaScript), shipped in the package, no build step.

So ``preview <- session <- server``.
"""

from __future__ import annotations

import html
import json
import logging
import os
import pathlib
import shutil
import tempfile
from collections.abc import Callable

from ..errors import InputError
from ..options import WarpOptions
from .server import EditServer
from .session import EditPaths, EditSession

__all__ = ["EditPaths", "EditServer", "EditSession", "redirect_page", "serve"]

log = logging.getLogger("warpcli")

#: The page the browser is sent to: it goes on to the editor's address (with the token) at once.
_REDIRECT = """<!DOCTYPE html>
<html><head><meta charset="utf-8"><title>warp edit</title>
<meta http-equiv="refresh" content="0;url={attr}">
<script>window.location.replace({script});</script>
</head><body><p><a href="{attr}">Open warp edit</a></p></body></html>
"""


def serve(
    image: str | os.PathLike[str],
    src: str | os.PathLike[str] | None = None,
    dst: str | os.PathLike[str] | None = None,
    output: str | os.PathLike[str] | None = None,
    options: WarpOptions | None = None,
    *,
    port: int = 0,
    browser: bool = True,
    announce: Callable[[str], None] | None = None,
) -> None:
    """Serve the editor for ``image`` until interrupted (Ctrl-C, `KeyboardInterrupt`).

    Parameters
    ----------
    image : path-like
        The image to warp (read, never written).
    src, dst : path-like or None
        The polygon files: loaded if they exist, saved there.
    output : path-like or None
        Where an export writes.
    options : WarpOptions or None
        The starting options.
    port : int
        0: any free port.
    browser : bool
        Open the page with `webbrowser`, through a private file (`redirect_page`): the token stays off
        the browser's command line.
    announce : callable or None
        Called with the page's address (with its token) once the server listens.

    Raises
    ------
    WarpError
        If the image or a polygon file cannot be read (`InputError`: also
        if the port cannot be listened on).
    """
    fs = (lambda p: None if p is None else os.fspath(p))
    paths = EditPaths.defaults(os.fspath(image), fs(src), fs(dst), fs(output))
    session = EditSession(paths, options)
    try:
        server = EditServer(session, port=port)
    except OSError as err:  # the port is taken, or needs privileges
        raise InputError(f"127.0.0.1:{port}: cannot listen there: {err.strerror or err}") from err
    if announce is not None:
        announce(server.url)
    page = None
    try:
        if browser:
            import webbrowser

            # Not the address itself: the browser is started with it on its command line, which
            # every local user can read in the process list. A file only the user can read sends it on.
            try:
                page = redirect_page(server.url)
            except OSError as err:
                log.warning("edit: cannot write the page that opens the editor (%s): open the printed address", err)
            else:
                webbrowser.open(pathlib.Path(page).as_uri())
        server.serve_forever()
    except KeyboardInterrupt:
        # Ctrl-C, the end of the process: a request's thread in the middle of an export dies with it,
        # and its pending and temporary files would stay beside the image (warpcli.outputs tracks every
        # one, the page's too). Only then: a server stopped otherwise leaves the process's other work be.
        from .._fork import kill_children
        from ..outputs import remove_temporaries

        kill_children()
        remove_temporaries()
        raise
    finally:
        server.shutdown()
        if page is not None:
            from ..outputs import track_temporary

            shutil.rmtree(os.path.dirname(page), ignore_errors=True)
            track_temporary(page, keep=False)
            track_temporary(os.path.dirname(page), directory=True, keep=False)


def redirect_page(url: str) -> str:
    """Write a page that sends the browser on to ``url``, in a new private directory; return its path.

    The way Jupyter opens its pages: a browser started with an address has
    it on its command line (``xdg-open URL``, ``firefox URL``), where every
    local user can read it, token and all. The browser is started with this
    file instead, in a directory only the user can enter (0700), readable by
    the user alone (0600). `serve` removes the directory when it stops, and a
    SIGTERM's end removes it too (`warpcli.outputs.track_temporary`).

    Parameters
    ----------
    url : str
        The editor's address, with its token.

    Returns
    -------
    str
        The page's absolute path.
    """
    from ..outputs import track_temporary

    directory = tempfile.mkdtemp(prefix="warp-edit-")  # 0700, a name no other user can take
    path = os.path.join(directory, "open.html")
    # A SIGTERM ends `warp edit` at once (warpcli.cli.run): the page with the token goes with it.
    track_temporary(directory, directory=True)
    track_temporary(path)
    text = _REDIRECT.format(attr=html.escape(url, quote=True), script=json.dumps(url).replace("<", "\\u003c"))
    try:
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_CLOEXEC", 0), 0o600)
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(text)
    except BaseException:
        shutil.rmtree(directory, ignore_errors=True)
        raise
    return path
