"""``warp edit``: a cage editor in the browser whose preview is the map itself, served on 127.0.0.1.

- `preview`: the image at preview size and the map at preview density, as a textured mesh;
- `session`: the image, the polygons, the options, saving and exporting through the pipeline;
- `server`: the HTTP server (standard library) and its checks: token, Host, Origin, sizes;
- ``static/``: the page (HTML, CSS, JavaScript), shipped in the package, no build step.

So ``preview <- session <- server``.
"""

from __future__ import annotations

import os
from collections.abc import Callable

from ..errors import InputError
from ..options import WarpOptions
from .server import EditServer
from .session import EditPaths, EditSession

__all__ = ["EditPaths", "EditServer", "EditSession", "serve"]


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
        Open the page with `webbrowser`.
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
    if browser:
        import webbrowser

        webbrowser.open(server.url)
    try:
        server.serve_forever()
    finally:
        server.shutdown()
