"""The editor's session: one image, its two polygons, the options, and what the page may ask of them."""

from __future__ import annotations

import dataclasses
import json
import math
import os
import shlex
import time
from dataclasses import dataclass

import numpy as np

from ..errors import InputError, PolygonError, WarpError
from ..maps.registry import METHODS, THETAS
from ..options import BOUNDARIES, INTERPOLATIONS, OUTSIDE, MapOptions, WarpOptions
from ..outputs import PendingOutputs, RunInputs, check_output_path, write_checked
from ..polygon import Polygon, check_pair
from ..raster.imageio import check_image_output, read_image
from .preview import PreviewImage, PreviewMapper, encode_png, preview_image, with_preview_density

#: The editor draws one polygon per side; a cage mesh file is refused with this line.
_CAGE_REFUSED = (
    "{name}: holds a cage mesh ({faces} faces); warp edit draws one polygon per side: edit a cage mesh as JSON "
    "(or several polygons in labelme) and warp it with warp --src/--dst"
)

__all__ = ["MAX_VERTICES", "EditPaths", "EditSession", "mirror_warning", "rotated_start", "rotated_start_warning"]

#: Most vertices a polygon from the page may have.
MAX_VERTICES = 2000
#: The options the page chooses, and the lists it chooses them from.
PAGE_CHOICES = {
    "method": tuple(METHODS),
    "theta": tuple(THETAS),
    "boundary": BOUNDARIES,
    "interp": INTERPOLATIONS,
    "outside": OUTSIDE,
}


@dataclass(frozen=True)
class EditPaths:
    """Where the editor reads and writes.

    The page names files to save by their name alone (no directory): they
    go into the image's directory. The paths given on the command line are
    the defaults and may lie anywhere.

    Parameters
    ----------
    image : str
        The image; read, never written.
    src, dst : str
        Where the polygons are read from if they exist, and saved.
    output : str
        Where an export writes the warped image.
    """

    image: str
    src: str
    dst: str
    output: str

    @classmethod
    def defaults(cls, image: str, src: str | None = None, dst: str | None = None, output: str | None = None) -> EditPaths:
        """The paths of a session, with ``IMAGE_STEM.src.json``, ``.dst.json`` and ``.warped.EXT`` beside the image by default."""
        stem, ext = os.path.splitext(image)
        return cls(image, src or f"{stem}.src.json", dst or f"{stem}.dst.json", output or f"{stem}.warped{ext}")

    @property
    def directory(self) -> str:
        """The image's directory: where names chosen on the page are saved."""
        return os.path.dirname(os.path.abspath(self.image))

    def chosen(self, name: object, default: str, extensions: tuple[str, ...]) -> str:
        """The path of a file name chosen on the page: ``default`` if it is its name, else NAME in the image's directory.

        Raises
        ------
        InputError
            If ``name`` is not a plain file name (a directory part, ``..``, a
            hidden name, spaces at either end, a control or format character
            such as DEL or a right-to-left override, which show a name other
            than the one written) with one of ``extensions``.
        """
        if name is None or name == "" or name == os.path.basename(default):
            return default
        if not isinstance(name, str) or len(name) > 255:
            raise InputError("a file name must be a text of at most 255 characters")
        if (
            name != os.path.basename(name) or "/" in name or "\\" in name or name.startswith(".")
            or name != name.strip() or any(_hidden_character(c) for c in name)
        ):  # fmt: skip
            raise InputError(f"{name!r}: give a file name alone; files are saved in the image's directory {self.directory}")
        if not name.lower().endswith(extensions):
            raise InputError(f"{name}: the name must end in {' or '.join(extensions)}")
        return os.path.join(self.directory, name)


def _hidden_character(c: str) -> bool:
    """A character that is not seen as itself in a file name: controls (C0, DEL, C1) and Unicode
    format characters (bidirectional overrides, zero-width joiners)."""
    import unicodedata

    return ord(c) < 32 or 0x7F <= ord(c) < 0xA0 or unicodedata.category(c) in ("Cf", "Cc", "Zl", "Zp")


def rotated_start(src: Polygon, dst: Polygon) -> int:
    """How far ``dst``'s vertices look rotated against ``src``'s: 0 when they correspond as numbered.

    Each polygon is centred and scaled to unit mean square radius; the shift
    k minimising the mean square distance between vertex i of ``src`` and
    vertex i + k of ``dst`` is the answer when it is less than a quarter of
    that of k = 0 (else 0: the shapes differ too much to tell).
    """
    if src.n != dst.n:
        return 0

    def normal(p: Polygon) -> np.ndarray:
        q = p.points - p.points.mean(axis=0)
        return q / math.sqrt(max((q**2).sum(axis=1).mean(), 1e-300))

    a, b = normal(src), normal(dst)
    # Error of shift k: mean over i of |a_i - b_(i+k)|^2, as (a - np.roll(b, -k)) gives it, for
    # every k at once (a drag asks for it at every move), a block of shifts at a time.
    n = src.n
    errors = np.empty(n)
    step = max(1, 65536 // n)
    for k0 in range(0, n, step):
        ks = np.arange(k0, min(n, k0 + step))
        errors[ks] = ((a[None] - b[(np.arange(n)[None, :] + ks[:, None]) % n]) ** 2).sum(axis=2).mean(axis=1)
    best = int(errors.argmin())
    return best if best != 0 and errors[best] < 0.25 * errors[0] else 0


def rotated_start_warning(src: Polygon, dst: Polygon) -> str | None:
    """The warning for a rotated start vertex, or None."""
    k = rotated_start(src, dst)
    if k == 0:
        return None
    return (
        f"{dst.name}: its vertex {k} sits where vertex 0 of {src.name} does: the start looks rotated by {k}, "
        "which twists the warp (renumber one polygon if that is not what you want)"
    )


def mirror_warning(src: Polygon, dst: Polygon) -> str | None:
    """The CLI's warning for polygons running in opposite directions, or None."""
    if (src.signed_area > 0) == (dst.signed_area > 0):
        return None
    return (
        f"{src.name} and {dst.name} run in opposite directions: the warp mirrors the image (reverse one file's vertex order "
        "if that is not what you want)"
    )


class EditSession:
    """The state the server keeps: the image, its preview, the paths, the options given on the command line.

    Parameters
    ----------
    paths : EditPaths
    options : WarpOptions
        The command line's options; the page changes those of `PAGE_CHOICES`.

    Raises
    ------
    WarpError
        If the image cannot be read, or an existing polygon file is bad.
    """

    def __init__(self, paths: EditPaths, options: WarpOptions | None = None) -> None:
        self.paths = paths
        self.options = options or WarpOptions()
        # The files the session reads and a save or an export must never replace: the image and the
        # command line's Theta and outline files (the page can choose those back, never others).
        self.inputs = tuple(p for p in (paths.image, self.options.map.theta_file, self.options.within_file) if p is not None)
        image = read_image(paths.image)
        self.image_size = (image.width, image.height)
        self.preview: PreviewImage = preview_image(image)
        self.png = encode_png(self.preview.pixels)
        self.mapper = PreviewMapper()
        self.initial = {side: self._existing(path) for side, path in (("src", paths.src), ("dst", paths.dst))}
        self._check_initial()
        # The polygons last checked, by side: in a drag one side stays the same and is not checked again.
        self._checked: dict[str, tuple[tuple, Polygon]] = {}
        self._in_preview: dict[str, tuple[Polygon, Polygon]] = {}

    def _check_initial(self) -> None:
        """Refuse polygon files the page cannot start from: it would show neither, and a save would replace them.

        The page draws the source first and starts the target as its copy: a
        target file without a source file, or one with another vertex count
        (which `warp` refuses too), cannot be shown, and saving would
        overwrite it unseen.
        """
        src, dst = self.initial["src"], self.initial["dst"]
        if dst is not None and src is None:
            raise InputError(
                f"{self.paths.dst}: exists, but {self.paths.src} does not: the page starts from the source polygon, "
                "and a save would replace this file unseen; give its source with --src, or another --dst"
            )
        if src is not None and dst is not None and len(src) != len(dst):
            raise PolygonError(
                f"{self.paths.dst}: has {len(dst)} vertices, but {self.paths.src} has {len(src)}: vertex i of one goes "
                "onto vertex i of the other (give --dst another name to start the target from the source)"
            )

    @staticmethod
    def _existing(path: str) -> list | None:
        """The polygon in ``path`` if the file exists (the CLI's errors if it is bad), else None."""
        if not os.path.exists(path):
            return None
        from ..polygon.partition import Partition, read_shape

        shape = read_shape(path)
        if isinstance(shape, Partition):
            raise PolygonError(_CAGE_REFUSED.format(name=path, faces=shape.n_faces))
        return shape.points.tolist()

    # --- what the page asks ------------------------------------------------------

    def state(self) -> dict:
        """What the page starts from: sizes, the polygons on disk, the choices, the options, the paths."""
        pw, ph = self.preview.preview_size
        return {
            "image": {"width": self.image_size[0], "height": self.image_size[1], "name": os.path.basename(self.paths.image)},
            "preview": {"width": pw, "height": ph, "factor": self.preview.factor},
            "src": self.initial["src"],
            "dst": self.initial["dst"],
            "choices": {k: list(v) for k, v in PAGE_CHOICES.items()},
            "help": {"method": {k: v.help for k, v in METHODS.items()}, "theta": {k: v.help for k, v in THETAS.items()}},
            "options": self.page_options(self.options),
            "names": {"src": self.paths.src, "dst": self.paths.dst, "output": self.paths.output},
            # Where the page's names are saved: the folder itself (".", the server's folder, means nothing in a browser).
            "directory": os.path.abspath(os.path.dirname(self.paths.image) or os.curdir),
        }

    @staticmethod
    def page_options(options: WarpOptions) -> dict:
        """The page's options (`PAGE_CHOICES`) of a `WarpOptions`."""
        return {
            "method": options.map.method, "theta": options.map.theta, "boundary": options.map.dst_boundary,
            "interp": options.interp, "outside": options.outside, "within": options.within,
        }  # fmt: skip

    def options_from(self, doc: object) -> WarpOptions:
        """The command line's options changed by the page's choices.

        Raises
        ------
        InputError
            If a choice is not one of `PAGE_CHOICES` (a Theta file given on
            the command line is also allowed).
        """
        if doc is None:
            return self.options
        if not isinstance(doc, dict):
            raise InputError("options must be an object")
        unknown = sorted(set(doc) - set(PAGE_CHOICES) - {"within"})
        if unknown:
            raise InputError(f"unknown option {unknown[0]!r}")
        within = self.within_from(doc.get("within", self.options.within))
        for key, value in doc.items():
            if key == "within":
                continue
            allowed = PAGE_CHOICES[key] + ((self.options.map.theta,) if key == "theta" else ())
            if value not in allowed:
                raise InputError(f"unknown {key} {value!r}; choose one of {', '.join(PAGE_CHOICES[key])}")
        mapping = self.options.map
        changes = {"method": doc.get("method", mapping.method), "theta": doc.get("theta", mapping.theta),
                   "dst_boundary": doc.get("boundary", mapping.dst_boundary)}  # fmt: skip
        # Within an outline the input is kept outside it (WarpOptions sets outside="input"); without, the page's outside.
        outside = doc.get("outside", self.options.outside)
        if within is None and self.options.within is not None and "outside" not in doc:
            outside = "background"
        return dataclasses.replace(
            self.options, map=dataclasses.replace(mapping, **changes),
            interp=doc.get("interp", self.options.interp), outside=outside, within=within,
        )  # fmt: skip

    def within_from(self, value: object) -> str | None:
        """The page's ``within``: None, ``"image"``, a margin in pixels, or the command line's own value.

        The page never names a file: a polygon file for the outline is only
        taken from the command line (``warp edit --within FILE``), and the
        page may choose it back; any other text is refused, as the CLI
        refuses a margin that is not a positive number of pixels.

        Raises
        ------
        InputError
            If ``value`` is none of those.
        """
        if value is None or value == self.options.within:
            return value  # type: ignore[return-value]
        if not isinstance(value, str) or len(value) > 255:
            raise InputError("within must be null, 'image' or a margin in pixels")
        text = value.strip()
        if text == "image":
            return text
        try:
            margin = float(text)
        except ValueError:
            raise InputError(f"--within {value}: choose image or a margin in pixels (a polygon file only from the command line)") from None
        if not (margin > 0 and math.isfinite(margin)):
            raise InputError(f"--within {value}: the margin must be a positive number of pixels")
        return text

    def polygons(self, doc: dict, src_path: str | None = None, dst_path: str | None = None) -> tuple[Polygon, Polygon]:
        """The page's two polygons, checked as the CLI checks polygon files, named after the files they are saved to.

        Raises
        ------
        PolygonError, InputError
            With the CLI's messages.
        """
        names = (src_path or self.paths.src, dst_path or self.paths.dst)
        out = []
        for side, name in zip(("src", "dst"), names):
            points = doc.get(side)
            if not isinstance(points, list) or len(points) > MAX_VERTICES:
                raise InputError(f"{name}: expected a list of at most {MAX_VERTICES} [x, y] pairs")
            out.append(self._polygon(side, points, name))
        check_pair(out[0], out[1])
        return out[0], out[1]

    def _polygon(self, side: str, points: list, name: str) -> Polygon:
        """``Polygon(points, name=name)``, reusing the one made last time for this side if nothing changed."""
        try:
            key = (side, name, json.dumps(points))
        except (TypeError, ValueError):
            return Polygon(points, name=name)  # not JSON numbers: Polygon says what is wrong
        kept = self._checked.get(side)
        if kept is not None and kept[0] == key:
            return kept[1]
        polygon = Polygon(points, name=name)
        self._checked[side] = (key, polygon)
        return polygon

    def _scaled(self, side: str, polygon: Polygon) -> Polygon:
        """``polygon`` in preview pixels (image point p is preview point p / factor); the one made last
        time for this side if it is the same polygon (in a drag, the side that does not move)."""
        k = self.preview.factor
        if k == 1:
            return polygon
        kept = self._in_preview.get(side)
        if kept is not None and kept[0] is polygon:
            return kept[1]
        scaled = Polygon(polygon.points / k, name=polygon.name)
        self._in_preview[side] = (polygon, scaled)
        return scaled

    @staticmethod
    def warnings(src: Polygon, dst: Polygon) -> list[str]:
        """The live warnings: mirrored, rotated start."""
        return [w for w in (mirror_warning(src, dst), rotated_start_warning(src, dst)) if w]

    def preview_map(self, doc: dict) -> bytes:
        """The preview mesh of the page's polygons and options (`PreviewMesh.to_bytes`); errors in the header.

        The polygons are scaled to the preview (image point p is preview
        point p / factor) and the map built there at the preview's density
        (`warpcli.edit.preview.preview_areas`), for a region the preview's size;
        the side named by ``doc["drag"]`` (being dragged) at the coarser drag
        density (`warpcli.edit.preview.with_preview_density`).
        """
        import struct

        try:
            src, dst = self.polygons(doc)
            options = self.options_from(doc.get("options"))
            drag = doc.get("drag")
            if drag not in (None, "src", "dst"):
                raise InputError(f"drag must be 'src', 'dst' or null, got {drag!r}")
            pw, ph = self.preview.preview_size
            region = (0.0, 0.0, float(pw), float(ph))
            if options.within is None:
                psrc, pdst = self._scaled("src", src), self._scaled("dst", dst)
                mapping = with_preview_density(options.map, psrc, pdst, drag)
                mesh = self.mapper.build(psrc, pdst, mapping, region)
            else:
                # The export's cage mesh (`warp --within`'s, in the image's pixels), mapped at the preview's
                # density (in the image's pixels: times factor^2) and shown shrunk to the preview.
                t0 = time.perf_counter()
                pair = self.mapper.within_pair(src, dst, options.within, self.image_size, drag)
                k = self.preview.factor
                mapping = with_preview_density(options.map, pair.src.outline, pair.dst.outline, drag)
                mesh = self.mapper.build_cage(pair.src, pair.dst, mapping, (0.0, 0.0, pw * k, ph * k), k)
                mesh = dataclasses.replace(mesh, seconds=time.perf_counter() - t0)  # the ring's cut counted too
        except WarpError as err:
            text = json.dumps({"ok": False, "error": str(err), "command": None}).encode()
            text += b" " * (-len(text) % 4)
            return struct.pack("<I", len(text)) + text
        header = {
            "ok": True, "warnings": self.warnings(src, dst), "max_area": list(mesh.max_area),
            "rebuilt": list(mesh.rebuilt), "seconds": round(mesh.seconds, 4),
            "command": self.command(options, self.paths.src, self.paths.dst, self.paths.output),
        }  # fmt: skip
        return mesh.to_bytes(header)

    @staticmethod
    def load(doc: dict) -> dict:
        """A polygon file's text from the page (a file the user chose), read as `read_polygon` reads a file.

        ``doc``: ``name`` (the file's name, for messages), ``text`` and
        ``label`` (which polygon of a labelme or GeoJSON file holding
        several; optional). Nothing is read from the disk.

        Returns
        -------
        dict
            ``points``: the polygon's vertices.
        """
        from ..polygon.formats import parse_json, points_of

        name, text, label = doc.get("name"), doc.get("text"), doc.get("label")
        if not isinstance(name, str) or not isinstance(text, str) or not (label is None or isinstance(label, str)):
            raise InputError("load: expected a file name, its text and an optional label")
        name = os.path.basename(name) or "polygon"
        parsed = parse_json(text.lstrip("\ufeff"), name)
        from ..polygon.partition import is_partition_document

        if is_partition_document(parsed, label):
            raise PolygonError(_CAGE_REFUSED.format(name=name, faces="several"))
        points = points_of(parsed, name, label)
        return {"points": Polygon(points, name=name).points.tolist()}

    # --- saving and exporting -------------------------------------------------------

    def save(self, doc: dict) -> dict:
        """Write the two polygon files, after checking every name and value of ``doc``: on any error nothing is written.

        Both files are written to pending names and renamed into place
        together (`warpcli.outputs.PendingOutputs`): a failure (a full disk)
        leaves both files as they were.

        Returns
        -------
        dict
            ``saved``: the two paths; ``warnings``; ``command``.

        Raises
        ------
        InputError, PolygonError
            A bad name, polygon or option; a name that is an input of the
            session (the image, the command line's Theta or outline file) or
            the other polygon's file as the session read it.
        ImageIOError
            If writing fails (before the renames: neither file is replaced).
        """
        plan = self._plan(doc)
        self._write(plan)
        return {"saved": [plan.src_path, plan.dst_path], "warnings": self.warnings(plan.src, plan.dst), "command": plan.command}

    def export(self, doc: dict) -> dict:
        """Save the polygons, then warp the whole image through the ordinary pipeline (`warpcli.pipeline.warp_file`).

        Everything is checked before the polygons are written, the output too
        (the same checks as `save`'s, and the output's format and that it is
        none of the session's inputs). The output is what the returned
        command line writes, byte for byte: the same call with the same options.
        """
        from ..pipeline import warp_file

        plan = self._plan(doc)
        check_image_output(plan.output, inputs=RunInputs((*self.inputs, plan.src_path, plan.dst_path)))
        self._write(plan)
        warp_file(self.paths.image, plan.output, plan.src_path, plan.dst_path, plan.options)
        return {"saved": [plan.src_path, plan.dst_path], "warnings": self.warnings(plan.src, plan.dst),
                "output": plan.output, "command": plan.command}  # fmt: skip

    def _plan(self, doc: dict) -> _SavePlan:
        """Every name and value a save or an export takes from ``doc``, checked; nothing is written here."""
        src_path = self.paths.chosen(doc.get("src_name"), self.paths.src, (".json",))
        dst_path = self.paths.chosen(doc.get("dst_name"), self.paths.dst, (".json",))
        output = self.paths.chosen(doc.get("output_name"), self.paths.output, _image_extensions(self.paths))
        if RunInputs((src_path,)).find(dst_path) is not None:  # the same path, or the same file by a link
            raise InputError(f"{dst_path}: the same file is given for both polygons")
        src, dst = self.polygons(doc, src_path, dst_path)
        options = self.options_from(doc.get("options"))
        command = self.command(options, src_path, dst_path, output)
        for side, path, other in (("src", src_path, self.paths.dst), ("dst", dst_path, self.paths.src)):
            # The other polygon's file, as the session read it, is the user's too: saving this
            # polygon over it would lose it (each side may replace its own file).
            if self.initial["dst" if side == "src" else "src"] is not None and RunInputs((other,)).find(path) is not None:
                raise InputError(f"{path}: would overwrite {other}, the other polygon's file; give each polygon its own file")
            check_output_path(path, inputs=RunInputs(self.inputs))
        texts = tuple(_file_text(path, polygon) for path, polygon in ((src_path, src), (dst_path, dst)))
        return _SavePlan(src_path, dst_path, output, src, dst, options, command, texts)

    @staticmethod
    def _write(plan: _SavePlan) -> None:
        """Write the two polygon files of a checked save, both or neither."""
        with PendingOutputs() as pending:
            for (path, _), text in zip(plan.files(), plan.texts):
                write_checked(pending.path(path), text.encode(), path)

    def command(self, options: WarpOptions, src_path: str, dst_path: str, output: str) -> str:
        """The ``warp ...`` command line that makes what an export makes."""
        return " ".join(shlex.quote(a) for a in command_args(options, self.paths.image, src_path, dst_path, output))


@dataclass(frozen=True)
class _SavePlan:
    """What a save writes and an export makes, every part checked (`EditSession._plan`)."""

    src_path: str
    dst_path: str
    output: str
    src: Polygon
    dst: Polygon
    options: WarpOptions
    command: str
    texts: tuple[str, str] = ("", "")

    def files(self) -> tuple[tuple[str, Polygon], tuple[str, Polygon]]:
        return (self.src_path, self.src), (self.dst_path, self.dst)


def _file_text(path: str, polygon: Polygon) -> str:
    """What saving ``polygon`` to ``path`` writes: a new file ``{"points": ...}``; a polygon file
    there already (plain, labelme, GeoJSON) keeps everything but its polygon's vertices
    (`warpcli.polygon.formats.with_points`). A file there that holds no one polygon is not
    replaced: a save would lose what it holds.

    Raises
    ------
    PolygonError
        If ``path`` holds something else.
    """
    from ..polygon.formats import read_document, with_points

    points = polygon.points.tolist()
    if not os.path.lexists(path):
        return json.dumps({"points": points}, indent=1) + "\n"
    try:
        name, doc = read_document(path)
        doc = with_points(doc, points, name)
    except PolygonError as err:
        raise PolygonError(f"{path}: exists and holds no one polygon a save can update ({err}); choose another name") from None
    return json.dumps(doc, indent=1, ensure_ascii=False) + "\n"


def _image_extensions(paths: EditPaths) -> tuple[str, ...]:
    ext = os.path.splitext(paths.output)[1].lower()
    return tuple(dict.fromkeys((ext, ".png", ".tif", ".tiff", ".exr", ".jpg", ".jpeg")))


def command_args(options: WarpOptions, image: str, src: str, dst: str, output: str) -> list[str]:
    """``warp IMAGE --src SRC --dst DST OUTPUT`` and an option for every value that is not the default.

    Raises
    ------
    InputError
        If an option has no command-line form (a (source, target) pair of ``max_area``).
    """
    args = ["warp", image, "--src", src, "--dst", dst, output]
    m, d = options.map, MapOptions()
    if isinstance(m.max_area, tuple) or not m.grade:
        raise InputError("max_area as a (source, target) pair, and grade=False, have no command-line form")
    flags = [
        ("--method", m.method, d.method), ("--theta", m.theta, d.theta),
        ("--max-area", None if m.max_area is None else repr(m.max_area), None), ("--weights", m.weights, d.weights),
        ("--src-boundary", m.src_boundary, d.src_boundary), ("--dst-boundary", m.dst_boundary, d.dst_boundary),
        ("--energy", m.energy, d.energy), ("--theta-start", m.theta_start, d.theta_start),
        ("--conditions", m.conditions, d.conditions), ("--nodes", None if m.nodes is None else str(m.nodes), None),
    ]  # fmt: skip
    w, dw = options, WarpOptions()
    flags += [
        ("--interp", w.interp, dw.interp), ("--outside", w.outside, "input" if w.within is not None else dw.outside),
        ("--vacated", w.vacated, dw.vacated),
        ("--dtype", w.dtype, dw.dtype), ("--compression", w.compression, dw.compression),
        ("--size", None if w.size is None else f"{w.size[0]}x{w.size[1]}", None),
    ]  # fmt: skip
    for flag, value, default in flags:
        if value != default:
            args += [flag, str(value)]
    bg = w.background if isinstance(w.background, tuple) else (w.background,)
    if tuple(float(v) for v in bg) != (0.0,):
        args += ["--background", ",".join(repr(float(v)) for v in bg)]
    if not w.antialias:
        args.append("--no-antialias")
    if w.within is not None:  # implies --outside input
        args += ["--within", w.within]
    return args
