"""The options the commands share (`warpcli.cli.options`): each group reaches a command as one object."""

from __future__ import annotations

import click
from click.testing import CliRunner

from warpcli.cli import points, warp
from warpcli.cli.options import (
    PolygonFiles,
    build_map_options,
    collected,
    map_options,
    polygon_options,
    resample_options,
)
from warpcli.options import MapOptions, WarpOptions

#: Every long option of warp, as the single-module CLI had them (the order of --help aside).
WARP_OPTIONS = {
    "--src", "--dst", "--src-label", "--dst-label", "--frames", "--inverse", "--out-dir", "--scheduler", "--jobs",
    "--out-name", "--interp", "--size", "--dtype", "--background", "--method", "--theta", "--boundary",
    "--src-boundary", "--dst-boundary", "--save-theta", "--energy", "--theta-start", "--nodes", "--conditions",
    "--max-area", "--antialias", "--outside", "--vacated", "--weights", "--report", "--grid", "--heatmap",
    "--heatmap-measure", "--save-map", "--save-forward-map", "--stmap-t", "--tiled", "--labels", "--verbose", "--quiet",
    "--version", "--frame",  # --frame: issue 23
    "--feather", "--within",  # issue 21
    "--compression",  # issue 24
}  # fmt: skip


def _echo_command(*decorators):
    """A command printing the keyword arguments it was called with."""

    def cmd(**kwargs):
        click.echo(repr(sorted(kwargs.items())))

    for decorate in reversed(decorators):
        cmd = decorate(cmd)
    return click.command()(cmd)


def test_warp_keeps_every_option():
    assert {o for p in warp.params for o in p.opts if o.startswith("--")} == WARP_OPTIONS


def test_a_group_of_options_reaches_the_command_as_one_object():
    cmd = _echo_command(polygon_options("s", "d", "label of --{side}"), map_options, resample_options)
    result = CliRunner().invoke(
        cmd, ["--src", "a.json", "--dst", "b.json", "--dst-label", "#1", "--boundary", "quadratic", "--size", "4x3"]
    )
    assert result.exit_code == 0, result.output
    expected = [
        ("mapping", MapOptions(dst_boundary="quadratic")),
        ("polygons", PolygonFiles("a.json", "b.json", None, "#1")),
        ("resampling", WarpOptions(size=(4, 3))),
    ]
    assert result.output == repr(expected) + "\n"


def test_options_appear_in_the_order_they_are_stacked():
    cmd = _echo_command(
        click.option("--first"), collected("both", dict, click.option("--second"), click.option("--third")),
        click.option("--fourth"),
    )  # fmt: skip
    assert [p.name for p in cmd.params] == ["first", "second", "third", "fourth"]
    result = CliRunner().invoke(cmd, ["--third", "3"])
    assert result.output == repr([("both", {"second": None, "third": "3"}), ("first", None), ("fourth", None)]) + "\n"


def test_the_label_help_names_its_side():
    helps = {p.name: p.help for p in points.params}
    assert helps["src_label"] == "Which polygon of a --src file holding several (a label or #N)."
    assert helps["dst_label"] == "Which polygon of a --dst file holding several (a label or #N)."


def test_boundary_sets_the_target_boundary_and_inverse_swaps_the_polygons():
    common = dict(method="fem", theta="regular", energy="conformal", theta_start="regular", nodes=None,
                  conditions="dirichlet", max_area=None, weights="cotan", src_boundary="linear")  # fmt: skip
    assert build_map_options(boundary=None, dst_boundary="quadratic", **common).dst_boundary == "quadratic"
    assert build_map_options(boundary="linear", dst_boundary="quadratic", **common).dst_boundary == "linear"
    pair = PolygonFiles("a.json", "b.json", "x", None)
    assert pair.swapped() == PolygonFiles("b.json", "a.json", None, "x")
