"""warp edit in a real headless Chromium: place vertices with the mouse, drag, preview pixels, undo, save, export."""

from __future__ import annotations

import contextlib
import json
import os
import shlex

import numpy as np
import pytest
from edit_helpers import (
    browser, drag, open_editor, place_polygon, preview_pixels, screen_point, served, skip_reason, wait_idle,
    write_smooth_image,
)  # fmt: skip

from warpcli import warp_image
from warpcli.cli import main
from warpcli.options import WarpOptions
from warpcli.polygon import Polygon, read_polygon

pytestmark = pytest.mark.skipif(skip_reason() is not None, reason=str(skip_reason()))

#: The preview against the library's warp of the preview image at that size (the same map: same
#: polygons, same max_area), away from the target's edge: mean and 99th percentile of the absolute
#: difference per channel, in 8-bit steps. What differs is how the points between the mesh's vertices
#: are found: the page interpolates f^-1 linearly over the target's mesh, the library evaluates it
#: at every pixel centre; and the GPU's bilinear weights have 8 bits.
MEAN_TOLERANCE, P99_TOLERANCE = 0.25, 2.0


def inside_mask(points: np.ndarray, width: int, height: int, margin: float) -> np.ndarray:
    """Pixel centres farther than ``margin`` from the polygon's edges: inside it (``margin`` > 0) or outside (< 0)."""
    y, x = np.mgrid[0:height, 0:width] + 0.5
    q = np.stack([x.ravel(), y.ravel()], axis=1)
    inside = np.zeros(len(q), bool)
    near = np.full(len(q), np.inf)
    for a, b in zip(points, np.roll(points, -1, axis=0)):
        crosses = (a[1] > q[:, 1]) != (b[1] > q[:, 1])
        with np.errstate(divide="ignore", invalid="ignore"):
            xc = a[0] + (q[:, 1] - a[1]) * (b[0] - a[0]) / (b[1] - a[1])
        inside ^= crosses & (q[:, 0] < xc)
        d = b - a
        t = np.clip(((q - a) @ d) / (d @ d), 0, 1)
        near = np.minimum(near, np.hypot(*(q - (a + t[:, None] * d)).T))
    side = inside if margin > 0 else ~inside
    return (side & (near > abs(margin))).reshape(height, width)


def octagon(cx: float, cy: float, rx: float, ry: float, n: int = 8) -> list[list[float]]:
    a = 2 * np.pi * np.arange(n) / n
    return [[round(cx + rx * np.cos(t), 1), round(cy + ry * np.sin(t), 1)] for t in a]


@pytest.fixture(scope="module")
def chromium_browser():
    with browser() as b:
        yield b


@contextlib.contextmanager
def octagon_drawn(tmp_path, chromium_browser):
    """A 320 x 240 image served, the page open, an octagon placed with the mouse and closed on vertex 0."""
    image = str(tmp_path / "picture.png")
    write_smooth_image(image, 320, 240)
    with served(image) as server:
        page = open_editor(chromium_browser, server)
        points = octagon(160, 120, 90, 70)
        place_polygon(page, points)
        wait_idle(page, 0)
        yield server, page, points


def test_draw_drag_preview_undo_save_export(tmp_path, chromium_browser):
    image = str(tmp_path / "picture.png")
    with octagon_drawn(tmp_path, chromium_browser) as (server, page, points):
        src = np.array(page.evaluate("() => window.warpEditor.src"))
        np.testing.assert_allclose(src, points, atol=0.6)  # one screen pixel is about 0.5 image pixel
        assert page.evaluate("() => window.warpEditor.closed")
        np.testing.assert_array_equal(page.evaluate("() => window.warpEditor.dst"), src)
        # Numbered vertices on both panels.
        assert page.locator("#src-svg text").all_text_contents() == [str(i) for i in range(8)]
        assert page.locator("#dst-svg text").all_text_contents() == [str(i) for i in range(8)]

        # Drag target vertex 2 (the bottom one) down and to the right.
        frames = page.evaluate("() => window.warpEditor.frames")
        start = src[2]
        drag(page, "dst", start, start + [25, 20])
        wait_idle(page, frames)
        dst = np.array(page.evaluate("() => window.warpEditor.dst"))
        np.testing.assert_allclose(dst[2], start + [25, 20], atol=0.6)
        np.testing.assert_array_equal(np.delete(dst, 2, axis=0), np.delete(src, 2, axis=0))
        header = page.evaluate("() => window.warpEditor.lastHeader")
        assert header["ok"] and header["rebuilt"] == ["target"]  # the source map was kept

        # The preview's pixels are the library's warp of the preview image at that size.
        shown = preview_pixels(page)
        k = page.evaluate("() => window.warpEditor.state.preview.factor")
        assert k == 1
        from warpcli.raster.imageio import read_image

        pixels = read_image(image).pixels
        want = warp_image(
            pixels, src / k, dst / k, WarpOptions(antialias=False), max_area=tuple(header["max_area"]), grade=False
        ).pixels
        mask = inside_mask(dst / k, 320, 240, margin=1.5)
        assert mask.sum() > 10_000
        diff = np.abs(shown[:, :, :3].astype(int) - want.astype(int))[mask]
        print(f"preview against the library: mean {diff.mean():.3f}, p99 {np.percentile(diff, 99):.1f}, max {diff.max()}")
        assert diff.mean() <= MEAN_TOLERANCE, diff.mean()
        assert np.percentile(diff, 99) <= P99_TOLERANCE, np.percentile(diff, 99)
        assert (shown[:, :, 3][mask] == 255).all()
        outside = inside_mask(dst / k, 320, 240, margin=-1.5)  # beyond the edge by 1.5 px: nothing drawn
        assert (shown[outside] == 0).all()

        # Undo puts the vertex back and redraws; redo moves it again.
        frames = page.evaluate("() => window.warpEditor.frames")
        page.keyboard.press("Control+z")
        wait_idle(page, frames)
        np.testing.assert_array_equal(page.evaluate("() => window.warpEditor.dst"), src)
        frames = page.evaluate("() => window.warpEditor.frames")
        page.click("#redo")
        wait_idle(page, frames)
        np.testing.assert_array_equal(page.evaluate("() => window.warpEditor.dst"), dst)

        # Save: the two polygon files, read back as the CLI reads them.
        page.click("#save")
        page.wait_for_function("() => document.getElementById('status').textContent.startsWith('wrote')")
        src_file, dst_file = tmp_path / "picture.src.json", tmp_path / "picture.dst.json"
        np.testing.assert_array_equal(read_polygon(src_file).points, src)
        np.testing.assert_array_equal(read_polygon(dst_file).points, dst)

        # Export, then run the command the page shows: the same bytes.
        page.select_option("#interp", "cubic")
        page.click("#export")
        page.wait_for_function("() => document.getElementById('status').textContent.includes('warped')", timeout=120_000)
        command = page.locator("#command").text_content()
        assert page.evaluate("() => window.warpEditor.lastError") == ""
        assert page.page_errors == []
    args = shlex.split(command)
    assert args[:2] == ["warp", image] and "--interp" in args and args[args.index("--interp") + 1] == "cubic"
    exported = tmp_path / "picture.warped.png"
    again = tmp_path / "again.png"
    args[args.index(str(exported))] = str(again)
    assert main(args[1:]) == 0
    assert exported.read_bytes() == again.read_bytes()


def test_bad_polygon_shows_the_cli_message(tmp_path, chromium_browser):
    image = str(tmp_path / "picture.png")
    write_smooth_image(image, 200, 160)
    square = [[40.0, 40.0], [160.0, 40.0], [160.0, 120.0], [40.0, 120.0]]
    (tmp_path / "a.json").write_text(json.dumps(square))
    with served(image, src=str(tmp_path / "a.json"), dst=str(tmp_path / "b.json")) as server:
        page = open_editor(chromium_browser, server)
        wait_idle(page, 0)
        frames = page.evaluate("() => window.warpEditor.frames")
        # Vertex 1 dragged past vertex 2's edge: the polygon crosses itself (a bow tie).
        drag(page, "dst", square[1], [100.0, 150.0])
        wait_idle(page, frames)
        shown = page.locator("#error").text_content()
        dst = page.evaluate("() => window.warpEditor.dst")
        with pytest.raises(Exception) as err:
            Polygon(dst, name=str(tmp_path / "b.json"))
        assert shown == str(err.value) and shown
        # Save refuses it with the same message and writes nothing.
        page.click("#save")
        page.wait_for_function("() => window.warpEditor.lastError !== ''")
        assert not (tmp_path / "b.json").exists()
        assert page.page_errors == []


def test_rotated_start_and_mirror_warnings_are_shown(tmp_path, chromium_browser):
    image = str(tmp_path / "picture.png")
    write_smooth_image(image, 200, 160)
    pts = np.array(octagon(100, 80, 60, 50))
    (tmp_path / "a.json").write_text(json.dumps(pts.tolist()))
    (tmp_path / "b.json").write_text(json.dumps(np.roll(pts, 3, axis=0).tolist()))
    with served(image, src=str(tmp_path / "a.json"), dst=str(tmp_path / "b.json")) as server:
        page = open_editor(chromium_browser, server)
        wait_idle(page, 0)
        warnings = page.locator("#warnings li").all_text_contents()
        assert len(warnings) == 1 and "its vertex 3 sits where vertex 0" in warnings[0]
    (tmp_path / "b.json").write_text(json.dumps(pts[::-1].tolist()))
    with served(image, src=str(tmp_path / "a.json"), dst=str(tmp_path / "b.json")) as server:
        page = open_editor(chromium_browser, server)
        wait_idle(page, 0)
        warnings = page.locator("#warnings li").all_text_contents()
        assert any("mirrors the image" in w for w in warnings)
        assert page.page_errors == []


def test_screenshot(tmp_path, chromium_browser, monkeypatch):
    """The README's picture: the sample's eye widened, pasted over the photograph, grid on.

    ``WARP_EDIT_SCREENSHOT=sample_images/edit.jpg`` keeps it (how the README's was made).
    """
    path = os.path.abspath(os.environ.get("WARP_EDIT_SCREENSHOT") or str(tmp_path / "editor.png"))
    monkeypatch.chdir(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # paths as the README's
    samples = "sample_images"
    with served(
        os.path.join(samples, "chelsea.png"), os.path.join(samples, "chelsea_eye.json"),
        os.path.join(samples, "chelsea_eye_wide.json"), "wide_eye.png", WarpOptions(outside="input"),
    ) as server:  # fmt: skip
        page = open_editor(chromium_browser, server, 1280, 680)
        wait_idle(page, 0)
        page.check("#grid")
        page.wait_for_timeout(100)
        page.screenshot(path=path, **({"quality": 85} if path.endswith((".jpg", ".jpeg")) else {}))
        assert os.path.getsize(path) > 10_000
        assert page.page_errors == []


def test_load_polygon_files_on_the_page(tmp_path, chromium_browser):
    image = str(tmp_path / "picture.png")
    write_smooth_image(image, 200, 160)
    pts = np.array(octagon(100, 80, 60, 50))
    (tmp_path / "a.json").write_text(json.dumps(pts.tolist()))
    labelme = {"shapes": [{"label": "x", "shape_type": "polygon", "points": (pts * 0.8 + 10).tolist()}]}
    (tmp_path / "b.json").write_text(json.dumps(labelme))
    with served(image) as server:
        page = open_editor(chromium_browser, server)
        page.set_input_files("#load-src", str(tmp_path / "a.json"))
        wait_idle(page, 0)
        np.testing.assert_array_equal(page.evaluate("() => window.warpEditor.src"), pts)
        frames = page.evaluate("() => window.warpEditor.frames")
        page.set_input_files("#load-dst", str(tmp_path / "b.json"))
        wait_idle(page, frames)
        np.testing.assert_array_equal(page.evaluate("() => window.warpEditor.dst"), pts * 0.8 + 10)
        assert page.evaluate("() => window.warpEditor.lastHeader.ok")
        (tmp_path / "c.json").write_text("[[0, 0], [1, 1]]")
        page.set_input_files("#load-dst", str(tmp_path / "c.json"))
        page.wait_for_function("() => window.warpEditor.lastError !== ''")
        assert page.locator("#error").text_content().startswith("c.json: ")
        np.testing.assert_array_equal(page.evaluate("() => window.warpEditor.dst"), pts * 0.8 + 10)
        # A target with another vertex count is refused: it used to replace the source with its copy.
        (tmp_path / "d.json").write_text(json.dumps(octagon(100, 80, 60, 50)[:6]))
        page.set_input_files("#load-dst", str(tmp_path / "d.json"))
        page.wait_for_function("() => window.warpEditor.lastError.startsWith('d.json: has 6 vertices')")
        np.testing.assert_array_equal(page.evaluate("() => window.warpEditor.src"), pts)
        np.testing.assert_array_equal(page.evaluate("() => window.warpEditor.dst"), pts * 0.8 + 10)
        # Keys after a click on a checkbox still reach the editor (Ctrl+Z undoes the last load).
        page.click("#grid")
        page.keyboard.press("Control+z")
        page.wait_for_function(f"() => window.warpEditor.dst[0][0] === {float(pts[0][0])}")
        assert page.page_errors == []


def test_within_control_preview_is_the_within_warp(tmp_path, chromium_browser):
    """Choosing within on the page: the whole image shows the within warp (cage and ring), the command says --within."""
    image = str(tmp_path / "picture.png")
    write_smooth_image(image, 160, 120)
    src = np.array([[50.0, 40.0], [110.0, 40.0], [110.0, 80.0], [50.0, 80.0]])
    dst = src + [[0, 0], [8, -6], [4, 5], [0, 0]]
    (tmp_path / "a.json").write_text(json.dumps(src.tolist()))
    (tmp_path / "b.json").write_text(json.dumps(dst.tolist()))
    from warpcli.raster.imageio import read_image

    pixels = read_image(image).pixels
    with served(image, src=str(tmp_path / "a.json"), dst=str(tmp_path / "b.json")) as server:
        page = open_editor(chromium_browser, server)
        wait_idle(page, 0)
        for kind, within in (("image", "image"), ("margin", "20")):
            frames = page.evaluate("() => window.warpEditor.frames")
            page.select_option("#within-kind", kind)
            wait_idle(page, frames)
            header = page.evaluate("() => window.warpEditor.lastHeader")
            assert header["ok"], header
            assert page.locator("#command").text_content().endswith(f"--within {within}")
            shown = preview_pixels(page)
            want = warp_image(pixels, src, dst, WarpOptions(within=within, antialias=False),
                              max_area=tuple(header["max_area"]), grade=False).pixels  # fmt: skip
            # Everywhere but the image's outer pixels (the outline, where the GPU's clamp and the paste differ).
            diff = np.abs(shown[1:-1, 1:-1, :3].astype(int) - want[1:-1, 1:-1].astype(int))
            print(f"within {within}: mean {diff.mean():.3f}, p99 {np.percentile(diff, 99):.1f}, max {diff.max()}")
            assert diff.mean() <= MEAN_TOLERANCE and np.percentile(diff, 99) <= P99_TOLERANCE
            assert (shown[:, :, 3] == 255).all()  # the whole image: the input outside the outline
        assert page.page_errors == []


def test_a_click_that_moves_nothing_is_no_undo_step(tmp_path, chromium_browser):
    # Each click on a vertex pushed an undo step that did nothing, and dropped the redo history;
    # Ctrl+Z in the middle of a drag restored a state the drag then went on editing.
    with octagon_drawn(tmp_path, chromium_browser) as (_, page, _points):
        steps = page.evaluate("() => window.warpEditor.past.length")
        target = np.array(page.evaluate("() => window.warpEditor.dst"))
        for _ in range(3):
            page.mouse.click(*screen_point(page, "dst", target[2]))
        assert page.evaluate("() => window.warpEditor.past.length") == steps
        # A drag is one step; Ctrl+Z mid-drag is ignored, and the drag's result stays.
        x, y = screen_point(page, "dst", target[2])
        page.mouse.move(x, y)
        page.mouse.down()
        page.mouse.move(x + 20, y + 10, steps=4)
        page.keyboard.press("Control+z")
        page.mouse.move(x + 30, y + 20, steps=4)
        page.mouse.up()
        assert page.evaluate("() => window.warpEditor.past.length") == steps + 1
        moved = np.array(page.evaluate("() => window.warpEditor.dst"))
        assert np.abs(moved[2] - target[2]).max() > 5
        page.keyboard.press("Control+z")
        np.testing.assert_array_equal(page.evaluate("() => window.warpEditor.dst"), target)
        page.keyboard.press("Control+y")
        np.testing.assert_array_equal(page.evaluate("() => window.warpEditor.dst"), moved)
        assert page.page_errors == []
