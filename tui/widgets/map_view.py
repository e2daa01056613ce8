"""The map: the mapper's occupancy grid with rovers, LIDAR, paths and a cursor.

Drawing uses half blocks: each character cell is two square pixels (the upper
half ``▀`` in the foreground colour, the lower half in the background colour),
since a terminal cell is about twice as tall as wide. One pixel is ``scale``
[cm] on a side; when a pixel covers several grid cells it shows the most
significant of them (occupied over free over unknown), so thin walls survive
zooming out. Rovers, the frontier target, the hide spot, guesses and the
cursor are characters drawn over the pixels.

The frame is the map frame of `tui.snapshot` (x right, y up on screen). What
each pixel shows, and the zoom steps, are `tui.widgets.map_pixels`.
"""

from __future__ import annotations

import math

import numpy as np
from rich.segment import Segment
from rich.style import Style
from textual.binding import Binding
from textual.geometry import Region, Size
from textual.message import Message
from textual.reactive import reactive
from textual.strip import Strip
from textual.widget import Widget

from tui.snapshot import GridView, Snapshot
from tui.widgets.map_pixels import (
    CODE,
    COLOURS,
    LIDAR_PX,
    PATH_PX,
    RANK,
    ROVER_COLOURS,
    TRUTH_LEGEND,
    TRUTH_LEGEND_CELLS,
    TRUTH_LEGEND_SHORT,
    UNKNOWN_PX,
    ZOOMS_CM,
    classify_values,
    fit_view,
    gather,
    heading_glyph,
    indexer,
    known_extent,
    same_raster,
)

__all__ = ["MapView"]


class MapView(Widget, can_focus=True):
    """The mapper's map with overlays, a cursor, zoom and pan.

    | Key | Action |
    |---|---|
    | arrows | move the cursor one character |
    | shift+arrows | pan a quarter of the view |
    | + / - | zoom in / out |
    | 0 | fit the known map (and follow it as it grows) |
    | r | rotate the cursor's heading by 45 deg (for the hide spot) |
    """

    BINDINGS = [
        Binding("up", "cursor(0, 1)", "Cursor", show=False),
        Binding("down", "cursor(0, -1)", "Cursor", show=False),
        Binding("left", "cursor(-1, 0)", "Cursor", show=False),
        Binding("right", "cursor(1, 0)", "Cursor", show=False),
        Binding("shift+up", "pan(0, 1)", "Pan", show=False),
        Binding("shift+down", "pan(0, -1)", "Pan", show=False),
        Binding("shift+left", "pan(-1, 0)", "Pan", show=False),
        Binding("shift+right", "pan(1, 0)", "Pan", show=False),
        Binding("plus,equals_sign", "zoom(-1)", "Zoom in", show=False),
        Binding("minus", "zoom(1)", "Zoom out", show=False),
        Binding("0", "fit", "Fit", show=False),
        Binding("r", "rotate", "Rotate", show=False),
    ]

    DEFAULT_CSS = """
    MapView {
        border: round $primary;
        border-title-color: $text;
        min-width: 20;
        min-height: 6;
    }
    MapView:focus { border: round $accent; }
    """

    show_truth: reactive[bool] = reactive(False)
    """Overlay ground truth: unseen obstacles dim blue, obstacles mapped free purple,
    free ground mapped occupied orange."""
    zoom: reactive[int] = reactive(3)
    """Index into `ZOOMS_CM`."""
    cursor: reactive[tuple[float, float]] = reactive((0.0, 0.0))
    """Cursor position (x, y) in the map frame [cm]."""
    cursor_heading: reactive[float] = reactive(90.0)
    """Heading [deg] proposed for the hide spot."""

    class Clicked(Message):
        """The map was clicked; the cursor moved to (x_cm, y_cm)."""

        def __init__(self, x_cm: float, y_cm: float) -> None:
            super().__init__()
            self.x_cm = x_cm
            self.y_cm = y_cm

    def __init__(self, *, name: str | None = None, id: str | None = None,
                 classes: str | None = None) -> None:
        super().__init__(name=name, id=id, classes=classes)
        self.snapshot: Snapshot | None = None
        self.center: tuple[float, float] = (0.0, 0.0)
        self._fitted = False
        self.auto_fit = True
        """Keep the known part of the map in view as it grows, until the person
        zooms or pans (``0`` turns it back on)."""
        self._lines: list[Strip] | None = None
        self._row_keys: list[tuple] = []  # what each drawn row showed, to refresh only changes
        self._samples: tuple | None = None  # (view key, xs, ys, {grid geometry: indexes})
        self._styles: dict[tuple, Style] = {}
        self._code_styles: dict[int, Style] = {}  # top * 16 + bottom class -> style

    def validate_zoom(self, value: int) -> int:
        return max(0, min(len(ZOOMS_CM) - 1, value))

    def watch_show_truth(self) -> None:
        self._invalidate()

    def watch_zoom(self) -> None:
        self._invalidate()

    def watch_cursor(self) -> None:
        self._follow_cursor()
        self._invalidate()

    def watch_cursor_heading(self) -> None:
        self._invalidate()

    @property
    def scale(self) -> float:
        """Pixel size [cm]."""
        return ZOOMS_CM[self.zoom]

    def update_snapshot(self, snapshot: Snapshot) -> None:
        """Show a new snapshot (fits the view to the map the first time)."""
        self.snapshot = snapshot
        if snapshot.map is not None and self.size.width > 0 and (
                not self._fitted or (self.auto_fit and self._needs_fit())):
            self._fitted = True
            self._fit()
            return
        self._update_titles()
        if self._lines is None or len(self._lines) != self._view_size()[1]:
            self._invalidate()
            return
        # Same view, new data: redraw now and repaint only the rows that changed
        # (Textual's per-line cost dominates the console's CPU use).
        old = self._row_keys
        self._lines = self._render_frame()
        changed = [y for y, key in enumerate(self._row_keys) if y >= len(old) or old[y] != key]
        width = self.size.width
        if changed:
            self.refresh(*(Region(0, y, width, 1) for y in changed))

    def _invalidate(self) -> None:
        """The view changed (zoom, pan, cursor, overlay, size): redraw every row."""
        self._lines = None
        self._row_keys = []
        self._update_titles()
        self.refresh()

    def _update_titles(self) -> None:
        x, y = self.cursor
        what = ""
        snap = self.snapshot
        if snap is not None and snap.map is not None:
            what = {-1: "unknown", 0: "free", 100: "occupied"}.get(
                snap.map.value_at(x, y), "?")
        title = f"Map {self.scale:g} cm/px"
        if self.show_truth:  # the whole legend where it fits in the top border, else short
            if len(title) + TRUTH_LEGEND_CELLS <= self.size.width - 4:
                title += TRUTH_LEGEND
            else:
                title = f"{self.scale:g}cm" + TRUTH_LEGEND_SHORT
        subtitle = f"({x:.0f}, {y:.0f}) cm @ {self.cursor_heading:.0f}° {what}"
        # Setting a border title repaints the whole widget, even to the same text.
        if title != self.border_title:
            self.border_title = title
        if subtitle != self.border_subtitle:
            self.border_subtitle = subtitle

    # -- geometry -------------------------------------------------------------
    def _view_size(self) -> tuple[int, int]:
        return max(1, self.size.width), max(1, self.size.height)

    def to_screen(self, x_cm: float, y_cm: float,
                  view: tuple[int, int] | None = None) -> tuple[int, int, int]:
        """(column, row, half) of a map point: the character cell and which half (0 top).

        ``view`` is the view's (width, height) when the caller has it (asking the
        widget for its size costs more than the arithmetic)."""
        w, h = view or self._view_size()
        s = self.scale
        px = math.floor((x_cm - self.center[0]) / s + w / 2)
        py = math.floor(h - (y_cm - self.center[1]) / s)  # pixel row from top, 2h rows
        return px, py // 2, py % 2

    def to_map(self, col: int, row: int, half: int = 0) -> tuple[float, float]:
        """The map point [cm] at the centre of a pixel."""
        w, h = self._view_size()
        s = self.scale
        py = 2 * row + half
        return (self.center[0] + (col + 0.5 - w / 2) * s,
                self.center[1] + (h - py - 0.5) * s)

    def _follow_cursor(self) -> None:
        w, h = self._view_size()
        col, row, _ = self.to_screen(*self.cursor)
        cx, cy = self.center
        if not 1 <= col < w - 1:
            cx = self.cursor[0]
        if not 0 <= row < h:
            cy = self.cursor[1]
        self.center = (cx, cy)

    # -- rendering --------------------------------------------------------------
    def get_content_width(self, container: Size, viewport: Size) -> int:
        return container.width

    def get_content_height(self, container: Size, viewport: Size, width: int) -> int:
        return container.height

    def on_resize(self) -> None:
        if not self._fitted and self.snapshot is not None and self.snapshot.map is not None:
            self._fitted = True
            self.action_fit()
        self._invalidate()

    def render_line(self, y: int) -> Strip:
        if self._lines is None:
            self._lines = self._render_frame()
        if 0 <= y < len(self._lines):
            return self._lines[y]
        return Strip.blank(self.size.width)

    def _style(self, fg: str, bg: str, bold: bool = False, reverse: bool = False) -> Style:
        key = (fg, bg, bold, reverse)
        style = self._styles.get(key)
        if style is None:
            style = self._styles[key] = Style(color=fg, bgcolor=bg, bold=bold, reverse=reverse)
        return style

    def pixel_classes(self) -> np.ndarray:
        """Class of every pixel of the current view, shape (2 * height, width)."""
        w, h = self._view_size()
        snap = self.snapshot
        s = self.scale
        grid = snap.map if snap is not None else None
        truth = snap.truth if (snap is not None and self.show_truth) else None
        res = grid.resolution_cm if grid is not None else s
        k = int(min(4, max(1, math.ceil(s / res))))
        key = (w, h, s, k, self.center)
        if self._samples is None or self._samples[0] != key:
            offs = (np.arange(k) + 0.5) / k - 0.5
            xs = self.center[0] + (np.arange(w) + 0.5 - w / 2) * s
            ys = self.center[1] + (h - np.arange(2 * h) - 0.5) * s
            gx = xs[None, :, None, None] + offs[None, None, :, None] * s
            gy = ys[:, None, None, None] + offs[None, None, None, :] * s
            self._samples = (key, *np.broadcast_arrays(gx, gy), {})
        _, gx, gy, indexers = self._samples

        n_samples = k * k
        if grid is not None and (truth is None or same_raster(grid, truth)):
            # Classify each cell once, then pick per pixel the most significant of its
            # samples as the largest code (rank above class): one gather and one max.
            cells = classify_values(grid.cells, None if truth is None else truth.cells,
                                    grid.cells.shape)
            codes = np.append(CODE[cells].reshape(-1), CODE[UNKNOWN_PX])  # last: outside
            index = self._sample_index(grid, indexers, gx, gy)  # (samples, 2h, w)
            out = (codes[index].max(axis=0) & 7).astype(np.int8)
        else:  # no map, or ground truth on another raster: sample both

            def values(g: GridView | None) -> np.ndarray | None:
                if g is None:
                    return None
                gkey = ("raw", g.cells.shape, g.origin_cm, g.resolution_cm)
                if gkey not in indexers:
                    indexers[gkey] = indexer(g, gx, gy)
                return gather(g, indexers[gkey])

            cls = classify_values(values(grid), values(truth), gx.shape)
            # significance: occupied/errors over free over unknown
            rank = RANK[cls]
            best = rank.reshape(2 * h, w, n_samples).argmax(axis=2)
            out = np.take_along_axis(cls.reshape(2 * h, w, n_samples), best[..., None], 2)[..., 0]
        if snap is None:
            return out
        for rover in snap.rovers:
            pts = rover.path
            for (x0, y0), (x1, y1) in zip(pts, pts[1:], strict=False):
                n = int(math.hypot(x1 - x0, y1 - y0) / (s / 2)) + 2
                self._plot(out, np.linspace(x0, x1, n), np.linspace(y0, y1, n), PATH_PX)
        if len(snap.lidar_points):
            self._plot(out, snap.lidar_points[:, 0], snap.lidar_points[:, 1], LIDAR_PX)
        return out

    @staticmethod
    def _sample_index(grid: GridView, indexers: dict, gx: np.ndarray,
                      gy: np.ndarray) -> np.ndarray:
        """Flat cell index of each sample point, the cell count where outside the grid,
        shape (samples per pixel, 2 * height, width): a max over the first axis is
        one pass over whole planes, over a short last axis it was ten times slower.
        Cached: it depends only on the view and the grid's geometry."""
        key = (grid.cells.shape, grid.origin_cm, grid.resolution_cm)
        index = indexers.get(key)
        if index is None:
            if len(indexers) > 8:  # a growing map changes geometry now and then
                indexers.clear()
            index = indexer(grid, gx, gy)
            index = np.where(index < 0, grid.cells.size, index).astype(np.intp)
            h2, w = index.shape[:2]
            index = np.ascontiguousarray(np.moveaxis(index.reshape(h2, w, -1), 2, 0))
            indexers[key] = index
        return index

    def _plot(self, out: np.ndarray, xs: np.ndarray, ys: np.ndarray, cls: int) -> None:
        h2, w = out.shape
        s = self.scale
        px = np.floor((xs - self.center[0]) / s + w / 2).astype(np.int64)
        py = np.floor(h2 / 2 - (ys - self.center[1]) / s).astype(np.int64)
        ok = (px >= 0) & (px < w) & (py >= 0) & (py < h2)
        out[py[ok], px[ok]] = cls

    def glyphs(self) -> dict[tuple[int, int], tuple[str, str]]:
        """Characters drawn over the pixels: (col, row) -> (char, colour)."""
        snap = self.snapshot
        marks: dict[tuple[int, int], tuple[str, str]] = {}
        if snap is None:
            return marks
        view = self._view_size()

        def put(x: float, y: float, char: str, colour: str) -> None:
            col, row, _ = self.to_screen(x, y, view)
            marks[(col, row)] = (char, colour)

        for i, (gx, gy) in enumerate(snap.seek_guesses):
            put(gx, gy, str(i + 1) if i < 9 else "?", "#ffd000")
        if snap.hide_spot is not None:
            put(snap.hide_spot.x_cm, snap.hide_spot.y_cm, "H", "#40ff60")
        for rover in snap.rovers:
            colour = ROVER_COLOURS.get(rover.role, "#ffffff")
            if rover.target is not None:
                put(*rover.target, "◎", colour)
            if self.show_truth and rover.true_pose is not None:
                put(rover.true_pose.x_cm, rover.true_pose.y_cm, "○", colour)
            if rover.pose is not None:
                put(rover.pose.x_cm, rover.pose.y_cm, heading_glyph(rover.pose.heading_deg),
                    colour)
        return marks

    def _render_frame(self) -> list[Strip]:
        """Strips for the whole view, one segment per run of equal cells (few segments
        per line keeps Textual's per-segment work small). Rows that show exactly what
        they showed last frame keep their strip."""
        w, h = view = self._view_size()
        cls = self.pixel_classes().astype(np.int32)
        codes = cls[0::2] * 16 + cls[1::2]  # (h, w): top and bottom class of each cell
        overlays: list[tuple[str, Style]] = []
        row_marks: dict[int, list[tuple[int, str, Style]]] = {}  # what each row overlays

        def overlay(col: int, row: int, char: str, style: Style) -> None:
            overlays.append((char, style))
            codes[row, col] = 256 + len(overlays) - 1
            row_marks.setdefault(row, []).append((col, char, style))

        for (col, row), (char, colour) in self.glyphs().items():
            if 0 <= col < w and 0 <= row < h:
                bg = COLOURS[cls[2 * row + 1, col]]
                overlay(col, row, char, self._style(colour, bg, bold=True))
        ccol, crow, _ = self.to_screen(*self.cursor, view)
        if 0 <= ccol < w and 0 <= crow < h:
            overlay(ccol, crow, heading_glyph(self.cursor_heading),
                    self._style("#000000", "#ffff00", bold=True))
        old_keys, old_lines = self._row_keys, self._lines or []
        row_bytes = codes.tobytes()
        stride = w * codes.itemsize
        styles = self._code_styles
        lines = []
        keys = []
        for row in range(h):
            key = (row_bytes[row * stride:(row + 1) * stride], tuple(row_marks.get(row, ())))
            keys.append(key)
            if row < len(old_lines) and row < len(old_keys) and old_keys[row] == key:
                lines.append(old_lines[row])
                continue
            line = codes[row]
            bounds = [0, *(np.flatnonzero(line[1:] != line[:-1]) + 1).tolist(), w]
            segs = []
            for a, b, code in zip(bounds, bounds[1:], line[bounds[:-1]].tolist(), strict=False):
                if code >= 256:
                    char, style = overlays[code - 256]
                    segs.append(Segment(char * (b - a), style))
                else:
                    style = styles.get(code)
                    if style is None:
                        style = styles[code] = self._style(COLOURS[code >> 4],
                                                           COLOURS[code & 15])
                    segs.append(Segment("▀" * (b - a), style))
            lines.append(Strip(segs, w))
        self._row_keys = keys
        return lines

    # -- events and actions -------------------------------------------------------
    def on_click(self, event) -> None:
        offset = event.get_content_offset(self)
        if offset is None:
            return
        self.cursor = self.to_map(offset.x, offset.y)
        self.post_message(self.Clicked(*self.cursor))

    def action_cursor(self, dx: int, dy: int) -> None:
        s = self.scale
        self.cursor = (self.cursor[0] + dx * s, self.cursor[1] + dy * 2 * s)

    def action_pan(self, dx: int, dy: int) -> None:
        self.auto_fit = False
        w, h = self._view_size()
        s = self.scale
        self.center = (self.center[0] + dx * w * s / 4, self.center[1] + dy * h * s / 2)
        self._invalidate()

    def action_zoom(self, step: int) -> None:
        self.auto_fit = False
        self.zoom += step
        self.center = self.cursor if self.snapshot is not None else self.center
        self._invalidate()

    def action_fit(self) -> None:
        """Zoom and centre on the known map, and keep doing so as it grows."""
        self.auto_fit = True
        self._fit()

    def _target_extent(self) -> tuple[float, float, float, float] | None:
        snap = self.snapshot
        if snap is None or snap.map is None:
            return None
        return known_extent(snap.map) or snap.map.extent_cm()

    def _needs_fit(self) -> bool:
        """The known map left the view, or would fit two zoom steps finer."""
        extent = self._target_extent()
        if extent is None:
            return False
        w, h = self._view_size()
        zoom, _ = fit_view(extent, w, h)
        s = self.scale
        cx, cy = self.center
        inside = (extent[0] >= cx - w * s / 2 and extent[2] <= cx + w * s / 2
                  and extent[1] >= cy - h * s and extent[3] <= cy + h * s)
        return not inside or zoom <= self.zoom - 2

    def _fit(self) -> None:
        extent = self._target_extent()
        if extent is None:
            return
        zoom, self.center = fit_view(extent, *self._view_size())
        self.set_reactive(MapView.zoom, zoom)
        self._invalidate()

    def action_rotate(self) -> None:
        self.cursor_heading = (self.cursor_heading + 45.0) % 360.0

    def toggle_truth(self) -> None:
        """Flip the ground-truth overlay."""
        self.show_truth = not self.show_truth
