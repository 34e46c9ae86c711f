"""Annotations carried by the image's map: a point stays on its pixel, labels are never blended,
a mask's warp is the image's support, and ``warp --labels`` writes them with the output or not at all."""

from __future__ import annotations

import os

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from helpers import run_cli, similarity, star, star_shaped, write_polygon
from warpcli import (
    BijectiveMap,
    InputError,
    Polygon,
    PolygonTransform,
    SamplingPlan,
    read_image,
    warp_boxes,
    warp_image,
    warp_labels,
    warp_points,
    write_image,
)
from warpcli.annotations import box_outlines


def _pair(seed: int):
    """A random star-shaped source and a target moved vertex by vertex (a generated bend, not a similarity)."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(5, 9))
    src = star_shaped(rng.uniform(0.6, 1.4, n), rng.uniform(0.6, 1.0, n))
    dst = star_shaped(rng.uniform(0.6, 1.4, n), rng.uniform(0.6, 1.0, n))
    return src, dst


def _inside(poly: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Even-odd point in polygon, written here so as not to use the code under test."""
    x, y = pts[:, 0:1], pts[:, 1:2]
    a, b = poly, np.roll(poly, -1, axis=0)
    cross = ((a[:, 1] > y) != (b[:, 1] > y)) & (x < (b[:, 0] - a[:, 0]) * (y - a[:, 1]) / (b[:, 1] - a[:, 1]) + a[:, 0])
    return cross.sum(axis=1) % 2 == 1


@settings(max_examples=5, deadline=None)
@given(seed=st.integers(0, 10_000))
def test_a_point_and_the_pixel_it_sits_on_stay_together(seed):
    """Distinct-colour dots at random points; the image warped with nearest; each point warped with
    warp_points lands on its own dot's colour in the warped image."""
    rng = np.random.default_rng(seed)
    src, dst = _pair(seed)
    size, half = 128, 2
    img = np.zeros((size, size, 3), np.uint8)
    # Pixel centres well inside the source, far enough apart that dots do not touch.
    cand = rng.integers(8, size - 8, (400, 2)) + 0.5
    cand = cand[_inside(src, cand)]
    dots = []
    for p in cand:
        if all(np.abs(p - q).max() > 2 * half + 2 for q in dots):
            dots.append(p)
        if len(dots) == 30:
            break
    dots = np.array(dots)
    colours = np.stack([np.arange(1, len(dots) + 1) * 7 % 256, np.arange(1, len(dots) + 1) * 3 + 20, np.full(len(dots), 200)], 1)
    assert len({tuple(c) for c in colours}) == len(dots)
    for (x, y), colour in zip(dots.astype(int), colours):
        img[y - half : y + half + 1, x - half : x + half + 1] = colour
    result = warp_image(img, src, dst, interp="nearest")
    moved = warp_points(dots, fmap=result)
    landed = 0
    for p, colour in zip(moved.points[moved.inside], colours[moved.inside]):
        c, r = int(p[0]), int(p[1])
        # A pixel whose centre is outside the target has no pre-image (the background), even if
        # the point, next to the edge, falls in it.
        if 0 <= c < size and 0 <= r < size and _inside(dst, np.array([[c + 0.5, r + 0.5]]))[0]:
            assert tuple(result.pixels[r, c]) == tuple(colour), (p, colour)
            landed += 1
    assert landed >= len(dots) // 2


def test_points_agree_with_the_map_and_flag_what_is_outside():
    src, dst = _pair(1)
    fmap = BijectiveMap.between(Polygon(src), Polygon(dst))
    p = np.array([[64.0, 64.0], [60.0, 70.0], [-50.0, 3.0]])
    moved = warp_points(p, src, dst)
    assert moved.inside.tolist() == [True, True, False]
    assert np.isnan(moved.points[2]).all()
    np.testing.assert_allclose(moved.points[:2], fmap.forward(p[:2]), atol=1e-12)
    back = warp_points(moved.points[:2], fmap=fmap, inverse=True)
    np.testing.assert_allclose(back.points, p[:2], atol=1e-7)
    # A PolygonTransform (scikit-image's coordinates) holds the same map.
    tf = PolygonTransform(src, dst, vertices="warpcli")
    np.testing.assert_allclose(warp_points(p[:2], fmap=tf).points, tf(p[:2] - 0.5) + 0.5, atol=1e-9)


def test_points_refuse_bad_input():
    src, dst = _pair(2)
    with pytest.raises(InputError, match=r"\(K, 2\)"):
        warp_points(np.zeros(3), src, dst)
    with pytest.raises(InputError, match="finite"):
        warp_points([[np.nan, 1.0]], src, dst)
    with pytest.raises(InputError, match="either"):
        warp_points([[1.0, 1.0]], src, dst, fmap=BijectiveMap.between(Polygon(src), Polygon(dst)))
    with pytest.raises(InputError, match="src and dst"):
        warp_points([[1.0, 1.0]], src)
    with pytest.raises(InputError, match="map"):
        warp_points([[1.0, 1.0]], fmap=42)


@settings(max_examples=4, deadline=None)
@given(scale=st.floats(0.7, 1.2), angle=st.floats(-0.8, 0.8))
def test_a_box_under_a_similarity_is_the_bounding_box_of_the_rotated_box(scale, angle):
    """Between similar polygons the map is that similarity (harmonic maps commute with it): the warped
    box is the bounding box of the box's corners moved by it, computed here independently."""
    src = star(6, 64, 60, 24, 54)
    dst = similarity(src, scale, angle, (4.0, -3.0), (64.0, 60.0))
    box = np.array([[56.0, 52.0, 72.0, 66.0]])
    out = warp_boxes(box, src, dst, samples=64)
    corners = np.array([[56, 52], [72, 52], [72, 66], [56, 66]], float)
    moved = similarity(corners, scale, angle, (4.0, -3.0), (64.0, 60.0))
    expect = np.concatenate([moved.min(0), moved.max(0)])
    np.testing.assert_allclose(out.boxes[0], expect, atol=0.05)
    assert out.inside.tolist() == [True]


def test_boxes_partly_or_wholly_outside():
    src, dst = _pair(3)
    boxes = np.array([[60.0, 60.0, 70.0, 70.0], [50.0, 50.0, 400.0, 70.0], [300.0, 300.0, 310.0, 310.0]])
    out = warp_boxes(boxes, src, dst)
    assert out.inside.tolist() == [True, False, False]
    assert np.isfinite(out.boxes[:2]).all() and np.isnan(out.boxes[2]).all()
    # The box holds the outline's points that have an image.
    ok = np.isfinite(out.outlines[1, :, 0])
    assert (out.boxes[1, :2] <= out.outlines[1, ok].min(0)).all() and (out.boxes[1, 2:] >= out.outlines[1, ok].max(0)).all()
    outline = box_outlines(boxes[:1], 4)
    assert outline.shape == (1, 16, 2)
    np.testing.assert_array_equal(outline[0, [0, 4, 8, 12]], [[60, 60], [70, 60], [70, 70], [60, 70]])


@pytest.mark.parametrize("seed", range(5))
def test_a_box_crossing_the_polygon_is_the_bounds_of_the_image_of_its_part_inside(seed):
    # The image of a box is that of its part inside SRC. Reference, independent of the boxes' code:
    # a dense grid of the box's points inside SRC (even-odd test written here), mapped one by one.
    # It used to be the outline's part alone: a box round the whole polygon was NaN, and one
    # crossing an edge missed the edge's image (the bounds of a mask warped alike disagreed).
    src, dst = _pair(seed)
    fmap = BijectiveMap.between(Polygon(src), Polygon(dst))
    rng = np.random.default_rng(seed)
    lo, hi = src.min(axis=0), src.max(axis=0)
    boxes = [np.r_[lo - 5, hi + 5]]  # round the whole polygon
    while len(boxes) < 8:
        a, b = rng.uniform(lo - 20, hi + 20, (2, 2))
        boxes.append(np.r_[np.minimum(a, b), np.maximum(a, b)])
    out = warp_boxes(np.array(boxes), fmap=fmap, samples=64)
    np.testing.assert_allclose(out.boxes[0], np.r_[dst.min(axis=0), dst.max(axis=0)], rtol=0, atol=1e-6)
    size = float(np.ptp(dst, axis=0).max())
    for k, box in enumerate(boxes):
        xs = np.linspace(box[0], box[2], 160)
        ys = np.linspace(box[1], box[3], 160)
        grid = np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)
        grid = grid[_inside(src, grid)]
        if len(grid) == 0:
            continue
        mapped = fmap.forward(grid)
        mapped = mapped[np.isfinite(mapped[:, 0])]
        ref = np.r_[mapped.min(axis=0), mapped.max(axis=0)]
        got = out.boxes[k]
        assert np.isfinite(got).all(), (k, box)
        # (The outline is sampled, 64 points an edge: where it bulges between them, a little short.)
        assert (got[:2] <= ref[:2] + 1e-3 * size).all() and (got[2:] >= ref[2:] - 1e-3 * size).all(), (k, got, ref)
        assert np.abs(got - ref).max() < 0.02 * size, (k, got, ref)


@pytest.mark.parametrize("dtype", [np.uint8, np.int8, np.uint16, np.int32, np.uint32, np.int64, np.uint64, bool])
def test_labels_are_a_subset_of_the_input_labels_in_their_own_type(dtype):
    rng = np.random.default_rng(int(np.dtype(dtype).itemsize))
    src, dst = _pair(4)
    if dtype is bool:
        values = np.array([False, True])
    else:
        info = np.iinfo(dtype)
        values = rng.integers(max(info.min, -(2**62)), min(info.max, 2**62), 12, dtype=np.int64).astype(dtype)
    seg = values[rng.integers(0, len(values), (16, 16))].repeat(8, 0).repeat(8, 1)
    result = warp_image(np.zeros((128, 128, 1), np.uint8), src, dst)
    out = warp_labels(seg, result)
    assert out.dtype == np.dtype(dtype) and out.shape == (128, 128)
    assert set(np.unique(out).tolist()) <= set(values.tolist()) | {0}
    inside = np.isfinite(result.inverse_map[..., 0])
    assert (out[~inside] == 0).all()
    # Large IDs stay exact: no float on the way (2**53 + 1 is not a float64).
    if dtype is np.int64:
        big = np.full((128, 128), 2**53 + 1, np.int64)
        assert set(np.unique(warp_labels(big, result)).tolist()) == {0, 2**53 + 1}


def test_labels_take_the_pixel_nearest_takes():
    """The same rule as the image resampler's nearest, on any map, window and output size."""
    src, dst = _pair(5)
    rng = np.random.default_rng(5)
    seg = rng.integers(0, 250, (128, 128, 2)).astype(np.uint8)
    for size in [(128, 128), (96, 140)]:
        fmap = BijectiveMap.between(Polygon(src), Polygon(dst))
        plan = SamplingPlan.from_map(fmap, *size, interp="nearest", antialias=False)
        np.testing.assert_array_equal(warp_labels(seg, plan), plan.render(seg))
        np.testing.assert_array_equal(warp_labels(seg, fmap, size), plan.render(seg))


def test_a_masks_warp_is_the_images_support_within_a_pixel():
    """A mask and an image that is the mask: the warped mask and the warped image's support (linear,
    antialiased) differ only at pixels that touch the other set (within one pixel)."""
    from scipy.ndimage import binary_dilation

    for seed in range(3):
        src, dst = _pair(seed + 10)
        rng = np.random.default_rng(seed)
        mask = np.zeros((128, 128), bool)
        for _ in range(4):
            x, y = rng.integers(20, 100, 2)
            mask[y : y + rng.integers(5, 30), x : x + rng.integers(5, 30)] = True
        result = warp_image(mask.astype(np.float32)[..., None], src, dst)
        support = result.pixels[..., 0] > 0.5
        warped = warp_labels(mask, result)
        assert warped.dtype == bool
        diff = warped ^ support
        ring = np.ones((3, 3), bool)
        assert not (diff & warped & ~binary_dilation(support, ring)).any()
        assert not (diff & support & ~binary_dilation(warped, ring)).any()
        assert diff.sum() < 0.2 * max(1, warped.sum())


def test_labels_refuse_what_they_cannot_do():
    src, dst = _pair(6)
    fmap = BijectiveMap.between(Polygon(src), Polygon(dst))
    with pytest.raises(InputError, match="does not fit"):
        warp_labels(np.zeros((4, 4), np.uint8), fmap, background=300)
    with pytest.raises(InputError, match="labels must be"):
        warp_labels(np.zeros(4, np.uint8), fmap)
    with pytest.raises(InputError, match=r"\(H, W, 2\)"):
        warp_labels(np.zeros((4, 4), np.uint8), np.zeros((4, 4)))


# --- the command line -------------------------------------------------------------------------------


def _files(tmp_path, seg_size=(96, 96)):
    from warpcli import RasterImage

    src, dst = _pair(7)
    src, dst = src * 0.75, dst * 0.75
    write_polygon(tmp_path / "src.json", src)
    write_polygon(tmp_path / "dst.json", dst)
    rng = np.random.default_rng(7)
    write_image(str(tmp_path / "in.png"), RasterImage(rng.integers(0, 255, (96, 96, 3)).astype(np.uint8)))
    seg = np.zeros(seg_size[::-1], np.uint16)
    seg[20:60, 30:70] = 1000
    seg[40:50, 40:50] = 7
    write_image(str(tmp_path / "seg.png"), RasterImage(seg[..., None]))
    return src, dst, seg


def test_cli_labels_go_through_the_images_map(tmp_path):
    src, dst, seg = _files(tmp_path)
    t = str(tmp_path)
    code, err = run_cli([f"{t}/in.png", "--src", f"{t}/src.json", "--dst", f"{t}/dst.json", f"{t}/out.png",
                 "--labels", f"{t}/seg.png", f"{t}/seg_out.png", "--size", "100x90"])  # fmt: skip
    assert code == 0, err
    got = read_image(f"{t}/seg_out.png")
    assert got.pixels.dtype == np.uint16 and got.pixels.shape == (90, 100, 1)
    expect = warp_labels(seg, warp_image(np.zeros((96, 96, 1), np.uint8), src, dst, size=(100, 90)))
    np.testing.assert_array_equal(got.pixels[..., 0], expect)
    assert set(np.unique(got.pixels).tolist()) <= {0, 7, 1000}


def test_cli_labels_of_another_size_leave_nothing_behind(tmp_path):
    _files(tmp_path, seg_size=(64, 96))
    t = str(tmp_path)
    before = sorted(os.listdir(t))
    code, err = run_cli([f"{t}/in.png", "--src", f"{t}/src.json", "--dst", f"{t}/dst.json", f"{t}/out.png",
                 "--labels", f"{t}/seg.png", f"{t}/seg_out.png"])  # fmt: skip
    assert code == 2
    assert "seg.png: labels are 64x96 but the image they annotate is 96x96" in err
    assert "Traceback" not in err
    assert sorted(os.listdir(t)) == before
    code, err = run_cli([f"{t}/in.png", "--src", f"{t}/src.json", "--dst", f"{t}/dst.json", f"{t}/out.png",
                 "--labels", f"{t}/seg.png", f"{t}/seg.png"])  # fmt: skip
    assert code == 2 and sorted(os.listdir(t)) == before
    code, err = run_cli([f"{t}/in.png", "--src", f"{t}/src.json", "--dst", f"{t}/dst.json", f"{t}/out.png",
                 "--labels", f"{t}/seg.png", f"{t}/seg_out.png", "--outside", "input"])  # fmt: skip
    assert code == 2 and "--outside input" in err and sorted(os.listdir(t)) == before


#: Which label types each format holds exactly, from the formats' documentation: PNG stores 8 and
#: 16-bit unsigned integers, BMP 8 bits, TIFF every type; OpenEXR stores 32-bit unsigned integers
#: and floats, and OpenImageIO writes 8 and 16-bit integers there as fractions of their maximum.
HOLDS = {
    "png": {"uint8", "uint16"}, "tif": {"uint8", "uint16", "uint32", "float32"},
    "exr": {"uint32", "float32"}, "bmp": {"uint8"}, "jpg": set(),
}  # fmt: skip
LABEL_VALUES = {"uint8": [7, 200], "uint16": [7, 1000], "uint32": [7, 3_000_000_000], "float32": [0.5, -3.0]}


@pytest.mark.parametrize("dtype", sorted(LABEL_VALUES))
@pytest.mark.parametrize("ext", sorted(HOLDS))
def test_cli_labels_are_written_exactly_or_refused_naming_the_file(tmp_path, dtype, ext):
    # 16-bit labels 256 and 300 written to BMP both became 1, JPEG made new labels at every edge:
    # a format is refused (lossy ones before any work) unless it gives every label back.
    from warpcli import RasterImage

    src, dst, _ = _files(tmp_path)
    t = str(tmp_path)
    seg = np.zeros((96, 96, 1), dtype)
    seg[20:60, 30:70], seg[40:50, 40:50] = LABEL_VALUES[dtype]
    write_image(f"{t}/seg.tif", RasterImage(seg))
    before = sorted(os.listdir(t))
    code, err = run_cli([f"{t}/in.png", "--src", f"{t}/src.json", "--dst", f"{t}/dst.json", f"{t}/out.png",
                         "--labels", f"{t}/seg.tif", f"{t}/seg_out.{ext}"])  # fmt: skip
    if dtype in HOLDS[ext]:
        assert code == 0, err
        got = read_image(f"{t}/seg_out.{ext}").pixels
        expect = warp_labels(seg[..., 0], warp_image(np.zeros((96, 96, 1), np.uint8), src, dst))
        np.testing.assert_array_equal(got[..., 0].astype(np.float64), expect.astype(np.float64))
    else:
        assert code == 2 and err.count("\n") == 1 and err.startswith(f"warp: error: {t}/seg_out.{ext}: "), err
        assert ("lossless format" if ext == "jpg" else "cannot hold these labels") in err
        assert sorted(os.listdir(t)) == before  # nor the image: the outputs go together


def test_cli_labels_belong_to_a_single_whole_image_warp(tmp_path):
    _files(tmp_path)
    t = str(tmp_path)
    before = sorted(os.listdir(t))
    common = ["--src", f"{t}/src.json", "--dst", f"{t}/dst.json", "--labels", f"{t}/seg.png", f"{t}/seg_out.png"]
    code, err = run_cli([f"{t}/in.png", f"{t}/out.tif", "--tiled", *common])
    assert code == 2 and "--labels needs the whole image" in err
    os.mkdir(f"{t}/outdir")
    code, err = run_cli([f"{t}/in.png", "--out-dir", f"{t}/outdir", *common])
    assert code == 2 and "--labels applies to a single warp" in err
    assert sorted(os.listdir(t)) == sorted(before + ["outdir"]) and not os.listdir(f"{t}/outdir")
