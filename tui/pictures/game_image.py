"""A recorded game as one picture: the final map with each rover's true and believed
trajectory, the hide spot, the seek guesses and where each fault began.

Drawn from a recording (`supervisors.recording`, read through `tui.replay.ReplayIndex`),
so it shows what the recording holds, ground truth included: this is the harness's
view of a game, never the firmware's or the server's. Frame: the map frame [cm]
(`tui.pictures.map_image`). Marks:

- true trajectory: a solid line in the rover's console colour;
- believed trajectory: a dashed line in the same colour;
- hide spot: a ring with a tick for its heading (hider colour);
- seek guesses: numbered crosses (seeker colour);
- fault onsets: red triangles at the faulted rover's true pose, with the fault kind.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from server.protocol import ROLES
from supervisors.recording.reading import Recording
from tui.pictures.map_image import DEFAULT_SCALE, MapCanvas, hex_rgb, map_canvas
from tui.replay.index import ReplayIndex
from tui.replay.system import map_from_room
from tui.snapshot import Pose
from tui.widgets.map_pixels import ROVER_COLOURS, UNKNOWN_PX

__all__ = ["FAULT_COLOUR", "game_picture"]

FAULT_COLOUR = "#ff4040"
"""Fault onset marks."""
_LEGEND_ROW_PX = 16
_DASH_PX = 6.0  # believed trajectory: dash and gap length [px]


def game_picture(rec: Recording, *, scale: int = DEFAULT_SCALE) -> Image.Image:
    """The picture of a recorded game (see the module docstring); ``scale`` pixels per
    map cell edge.

    Raises:
        ValueError: a bad ``scale``.
    """
    index = ReplayIndex(rec, map_from_room(rec))
    end = rec.end_s
    tracks = {role: (index.track(role, "true"), index.track(role, "believed"))
              for role in ROLES}
    hide, guesses = index.commands(end)
    points = [(p.x_cm, p.y_cm) for true, believed in tracks.values() for _, p in true + believed]
    points += list(guesses) + ([(hide.x_cm, hide.y_cm)] if hide else [])
    canvas = _canvas(index, end, points, scale)
    draw = ImageDraw.Draw(canvas.image)
    width = max(1, scale // 2)
    for role, (true, believed) in tracks.items():
        colour = hex_rgb(ROVER_COLOURS.get(role, "#ffffff"))
        _dashed(draw, [canvas.pixel(p.x_cm, p.y_cm) for _, p in believed], colour, width)
        if len(true) > 1:
            draw.line([canvas.pixel(p.x_cm, p.y_cm) for _, p in true], fill=colour, width=width + 1,
                      joint="curve")
    font = ImageFont.load_default()
    r = 3 * scale
    if hide is not None:
        x, y = canvas.pixel(hide.x_cm, hide.y_cm)
        colour = hex_rgb(ROVER_COLOURS["hider"])
        draw.ellipse((x - r, y - r, x + r, y + r), outline=colour, width=2)
        h = math.radians(hide.heading_deg)
        draw.line((x, y, x + 1.6 * r * math.cos(h), y - 1.6 * r * math.sin(h)), fill=colour,
                  width=2)
    for i, (gx, gy) in enumerate(guesses, 1):
        x, y = canvas.pixel(gx, gy)
        colour = hex_rgb(ROVER_COLOURS["seeker"])
        draw.line((x - r, y - r, x + r, y + r), fill=colour, width=2)
        draw.line((x - r, y + r, x + r, y - r), fill=colour, width=2)
        draw.text((x + r + 2, y - r), str(i), fill=colour, font=font)
    fault_rgb = hex_rgb(FAULT_COLOUR)
    for fault in index.all_faults():
        where = _pose_at(tracks.get(_role_of(fault.target), ([], []))[0], fault.started_s)
        if where is None:
            continue
        x, y = canvas.pixel(where.x_cm, where.y_cm)
        draw.polygon([(x, y - r), (x - r, y + r), (x + r, y + r)], outline=fault_rgb, width=2)
        draw.text((x + r + 2, y), f"{fault.kind} {fault.target}", fill=fault_rgb, font=font)
    return _with_legend(canvas.image, rec, font)


def _canvas(index: ReplayIndex, t: float, points: Sequence[tuple[float, float]],
            scale: int) -> MapCanvas:
    """The final map, grown with unknown cells to hold every point (and a margin)."""
    grid = index.map(t)
    if grid is None:
        cells, res, origin = np.full((1, 1), -1, np.int8), 5.0, (0.0, 0.0)
    else:
        cells, res, origin = grid.cells, grid.resolution_cm, grid.origin_cm
    classes = np.where(cells == 100, 2, np.where(cells == 0, 1, UNKNOWN_PX)).astype(np.int8)
    ny, nx = classes.shape
    xs = [p[0] for p in points] or [origin[0]]
    ys = [p[1] for p in points] or [origin[1]]
    margin = 4  # cells round the farthest point
    left = max(0, math.ceil((origin[0] - min(xs)) / res) + margin)
    below = max(0, math.ceil((origin[1] - min(ys)) / res) + margin)
    right = max(0, math.ceil((max(xs) - origin[0]) / res) - nx + margin)
    above = max(0, math.ceil((max(ys) - origin[1]) / res) - ny + margin)
    grown = np.pad(classes, ((below, above), (left, right)), constant_values=UNKNOWN_PX)
    return map_canvas(grown, res, (origin[0] - left * res, origin[1] - below * res),
                      scale=scale)


def _dashed(draw: ImageDraw.ImageDraw, pixels: Sequence[tuple[float, float]],
            colour: tuple[int, int, int], width: int) -> None:
    """A dashed polyline: `_DASH_PX` on, `_DASH_PX` off, along its length."""
    travelled = 0.0
    for (x0, y0), (x1, y1) in zip(pixels, pixels[1:], strict=False):
        length = math.hypot(x1 - x0, y1 - y0)
        if length > 0 and int(travelled // _DASH_PX) % 2 == 0:
            draw.line((x0, y0, x1, y1), fill=colour, width=width)
        travelled += length


def _role_of(target: str) -> str:
    """``mapper/lidar`` or ``mapper.lidar`` -> ``mapper``."""
    return target.replace(".", "/").split("/")[0]


def _pose_at(track: Sequence[tuple[float, Pose]], t: float) -> Pose | None:
    """The last pose of ``track`` at or before ``t`` (the first one before it began)."""
    best = None
    for when, pose in track:
        if when > t and best is not None:
            break
        best = pose
    return best


def _with_legend(image: Image.Image, rec: Recording, font: ImageFont.ImageFont) -> Image.Image:
    """The picture with a band below: what it shows, and each mark's meaning."""
    s = rec.summary
    title = (f"{rec.run.scenario_ref} seed {rec.run.seed}: {s.get('outcome', 'cut short')}"
             f" at {rec.end_s:.1f} s")
    rows = [[(title, (230, 230, 230))],
            [(f"{role}: solid true, dashed believed", hex_rgb(ROVER_COLOURS[role]))
             for role in ROLES],
            [("o hide spot", hex_rgb(ROVER_COLOURS["hider"])),
             ("x seek guesses", hex_rgb(ROVER_COLOURS["seeker"])),
             ("^ fault onset", hex_rgb(FAULT_COLOUR))]]
    width = max(image.width, 560)
    out = Image.new("RGB", (width, image.height + _LEGEND_ROW_PX * len(rows) + 6), (0, 0, 0))
    out.paste(image, (0, 0))
    draw = ImageDraw.Draw(out)
    for i, row in enumerate(rows):
        x, y = 4, image.height + 3 + i * _LEGEND_ROW_PX
        for text, colour in row:
            draw.text((x, y), text, fill=colour, font=font)
            x += int(draw.textlength(text, font=font)) + 14
    return out
