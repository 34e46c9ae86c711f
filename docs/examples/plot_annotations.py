"""Keypoints and a label image carried with the picture

One map moves everything: the image (`warpcli.warp_image`), its keypoints
(`warpcli.warp_points`, NaN and ``inside=False`` for a point outside the
polygon) and its segmentation (`warpcli.warp_labels`, resampled with nearest
so labels are never blended: every output label is an input label or 0).
The picture shows the input and the warped image, each with its labels
tinted over it and its keypoints as white squares.
"""

from pathlib import Path

import numpy as np

import warpcli

SAMPLES = Path(__file__).resolve().parents[2] / "sample_images"
image = warpcli.read_image(SAMPLES / "grid.png").pixels
src = warpcli.read_polygon(SAMPLES / "grid_L.json")
dst = warpcli.read_polygon(SAMPLES / "grid_hexagon.json")

labels = np.zeros(image.shape[:2], np.int32)  # a segmentation: three objects
labels[80:220, 80:240] = 1
labels[300:440, 90:200] = 2
labels[320:420, 300:440] = 3
points = np.array([[150.5, 150.5], [145.5, 370.5], [370.5, 370.5], [500.0, 20.0]])  # the last is outside the L

result = warpcli.warp_image(image, src, dst)
labels_out = warpcli.warp_labels(labels, result)  # the same map, the same output size
moved = warpcli.warp_points(points, fmap=result)
print("labels in:", np.unique(labels).tolist(), "out:", np.unique(labels_out).tolist())
print("keypoints inside:", moved.inside.tolist())
print(np.round(moved.points, 2))

TINTS = np.array([[0, 0, 0], [255, 60, 60], [60, 200, 60], [60, 90, 255]], np.float64)


def overlay(pixels, seg, pts):
    out = pixels[..., :3].astype(np.float64)
    tinted = seg > 0
    out[tinted] = 0.45 * out[tinted] + 0.55 * TINTS[seg[tinted]]
    for x, y in pts[np.isfinite(pts).all(axis=1)]:
        c, r = int(x), int(y)
        out[max(r - 5, 0) : r + 6, max(c - 5, 0) : c + 6] = 255
    return out.astype(np.uint8)


side = np.concatenate([overlay(image, labels, points), overlay(result.pixels, labels_out, moved.points)], axis=1)
warpcli.write_image("annotations.png", warpcli.RasterImage(side))
