"""How the cage's width shapes a bend

The same bend, drawn with two cages around a straight bar: a narrow cage
hugging the bar, and a wide one with room around it. Every cage vertex moves
by the same arc. The map is harmonic, so each point moves as an average of
how the cage's edges move around it: inside the narrow cage the bar follows
the edges closely and bends as drawn; inside the wide cage the bend is
spread over the whole area it encloses, so the bar bends more softly and
its surroundings move with it (in the middle, the wide cage's bar moves
about half as far as its edges: a harmonic bend fades like
``cosh(pi y / L)`` across a cage of length ``L``). Draw the cage tight
around what should bend, and wide where the bend should fade out.
"""

import numpy as np

import warpcli

size = 512
y, x = np.mgrid[0:size, 0:size]
image = np.full((size, size, 3), 235, np.uint8)
image[(x // 16 + y // 16) % 2 == 0] = 205  # a checker shows the deformation
bar = (y >= 236) & (y < 276) & (x >= 40) & (x < 472)
image[bar] = [40, 90, 200]
image[bar & ((x // 24) % 2 == 0)] = [230, 120, 30]

xs = np.linspace(30, 482, 9)


def cage(half_height):
    top = [[v, 256 - half_height] for v in xs]
    bottom = [[v, 256 + half_height] for v in xs[::-1]]
    return np.array(top + bottom)


def bent(points, depth=90.0):
    out = points.copy()
    out[:, 1] += depth * np.sin(np.pi * (points[:, 0] - xs[0]) / (xs[-1] - xs[0]))
    return out


panels = []
for half_height in (40, 200):
    src = cage(half_height)
    result = warpcli.warp_image(image, src, bent(src), background=1.0)  # white outside the cage
    report = warpcli.build_report(result)
    print("cage half-height %3d px: conformal mean %.3f, max %.2f" % (half_height, report["conformal"]["mean"], report["conformal"]["max"]))
    panels.append(result.pixels)
warpcli.write_image("narrow_and_wide_cage.png", warpcli.RasterImage(np.concatenate(panels, axis=1)))
