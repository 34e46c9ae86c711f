"""A warpcli map inside scikit-image

`warpcli.PolygonTransform` is called as scikit-image's transforms are:
``(K, 2)`` arrays of ``(x, y)`` with pixel centres at whole numbers. Pass its
``inverse`` to ``skimage.transform.warp``; points outside the target go far
away, so ``warp`` fills them with ``cval`` (not NaN). The result is warpcli's
own warp to interpolation accuracy.
"""

from pathlib import Path

import numpy as np
from skimage.transform import warp

import warpcli

SAMPLES = Path(__file__).resolve().parents[2] / "sample_images"
image = warpcli.read_image(SAMPLES / "chelsea.png").pixels / 255.0
src = warpcli.read_polygon(SAMPLES / "chelsea_ring.json")
dst = warpcli.read_polygon(SAMPLES / "chelsea_star.json")

tf = warpcli.PolygonTransform(src, dst, vertices="warpcli")  # the polygon files use warpcli's convention
theirs = warp(image, tf.inverse, order=1, cval=1.0)  # white outside the star
ours = warpcli.warp_image(image, src, dst, antialias=False, background=1.0).pixels

inside = np.isfinite(warpcli.warp_image(image[..., :1], src, dst, antialias=False).inverse_map[..., 0])
print("largest difference inside the star: %.2g" % np.abs(theirs - ours)[inside].max())
print("tf([[225, 150]]) =", np.round(tf([[225.0, 150.0]]), 3))
warpcli.write_image("skimage_warp.png", warpcli.RasterImage(np.round(theirs * 255).astype(np.uint8)))
