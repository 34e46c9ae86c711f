"""Helpers of the editor's tests: a smooth test image, a served session, and Chromium from the system."""

from __future__ import annotations

import contextlib
import os
import shutil

import numpy as np

from warpcli.edit import EditPaths, EditServer, EditSession
from warpcli.raster.imageio import RasterImage, write_image

#: Arguments Chromium needs for WebGL without a GPU (the software renderer).
CHROMIUM_ARGS = ["--enable-unsafe-swiftshader", "--use-angle=swiftshader", "--ignore-gpu-blocklist"]


def smooth_image(width: int, height: int, channels: int = 3) -> np.ndarray:
    """A smooth colourful uint8 picture (slow waves): bilinear sampling of it is accurate, so pixels compare tightly."""
    y, x = np.mgrid[0:height, 0:width].astype(float)
    planes = [
        0.5 + 0.45 * np.sin(x / 23.0) * np.cos(y / 31.0),
        0.5 + 0.45 * np.cos((x + y) / 37.0),
        0.5 + 0.45 * np.sin((x - 2 * y) / 29.0),
    ]
    px = np.stack(planes[:channels], axis=2)
    return np.round(px * 255).astype(np.uint8)


def write_smooth_image(path: str, width: int, height: int) -> None:
    write_image(path, RasterImage(smooth_image(width, height), ("R", "G", "B")))


def chromium() -> str | None:
    """The system's Chromium, or None."""
    return shutil.which("chromium") or shutil.which("chromium-browser")


def skip_reason() -> str | None:
    """Why the browser tests cannot run here, or None."""
    try:
        import playwright.sync_api  # noqa: F401
    except ImportError:
        return "playwright is not installed (pip install -e '.[test]')"
    if chromium() is None:
        return "no chromium on PATH (Debian: apt-get install chromium)"
    return None


@contextlib.contextmanager
def served(image: str, src: str | None = None, dst: str | None = None, output: str | None = None, options=None):
    """An editor server for ``image`` on a thread, shut down on exit."""
    server = EditServer(EditSession(EditPaths.defaults(image, src, dst, output), options))
    server.start()
    try:
        yield server
    finally:
        server.shutdown()


@contextlib.contextmanager
def browser():
    """A headless Chromium page (the system's binary, driven by Playwright)."""
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=chromium(), args=CHROMIUM_ARGS)
        try:
            yield b
        finally:
            b.close()


def open_editor(b, server: EditServer, width: int = 1400, height: int = 860):
    """A page on the editor, once it has started, under the page's own Content-Security-Policy.

    Playwright's waits and evaluations are given as functions (``"() => ..."``): an expression
    would be evaluated by ``eval``, which that policy forbids.
    """
    page = b.new_page(viewport={"width": width, "height": height})
    # Scripts' exceptions and the console's errors (a Content-Security-Policy violation, a refused request).
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
    page.goto(server.url)
    page.wait_for_function("() => window.warpEditor && window.warpEditor.ready", timeout=60_000)
    page.page_errors = errors  # type: ignore[attr-defined]
    return page


def wait_idle(page, frames_before: int | None = None) -> None:
    """Wait until no preview is being fetched (and, given ``frames_before``, a new one was drawn)."""
    cond = "() => window.warpEditor.idle()"
    if frames_before is not None:
        cond += f" && window.warpEditor.frames > {frames_before}"
    page.wait_for_function(cond, timeout=60_000)


def screen_point(page, side: str, point) -> tuple[float, float]:
    """Where image point ``point`` is on the screen in the ``side`` panel ("src" or "dst")."""
    box = page.locator(f"#{side}-svg").bounding_box()
    view = page.evaluate("() => [window.warpEditor.state.preview.width * window.warpEditor.state.preview.factor,"
                         " window.warpEditor.state.preview.height * window.warpEditor.state.preview.factor]")
    return box["x"] + point[0] * box["width"] / view[0], box["y"] + point[1] * box["height"] / view[1]


def place_polygon(page, points) -> None:
    """Click the vertices on the source panel, then vertex 0 again to close the polygon."""
    for p in points:
        page.mouse.click(*screen_point(page, "src", p))
    page.mouse.click(*screen_point(page, "src", points[0]))


def drag(page, side: str, start, end, steps: int = 8) -> None:
    """Drag with the mouse from image point ``start`` to ``end`` on a panel."""
    page.mouse.move(*screen_point(page, side, start))
    page.mouse.down()
    page.mouse.move(*screen_point(page, side, end), steps=steps)
    page.mouse.up()


def preview_pixels(page) -> np.ndarray:
    """The preview canvas's RGBA pixels, as the page drew them."""
    import base64

    w, h = page.evaluate("() => [window.warpEditor.state.preview.width, window.warpEditor.state.preview.height]")
    raw = base64.b64decode(page.evaluate("() => window.warpEditor.previewPixels()"))
    return np.frombuffer(raw, np.uint8).reshape(h, w, 4)


def snapshot_dir(directory: str) -> dict:
    """Every file under ``directory`` with its size and modification time."""
    out = {}
    for root, _, files in os.walk(directory):
        for name in files:
            path = os.path.join(root, name)
            st = os.stat(path)
            out[path] = (st.st_size, st.st_mtime_ns)
    return out
