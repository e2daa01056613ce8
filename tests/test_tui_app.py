"""The console driven headless: keys are posted (a running simulation never goes idle,
so ``pilot.press`` would stall) and each test polls for the effect on screen and on
what the fake system's controller received."""

from __future__ import annotations

import asyncio
import dataclasses
import io
from collections.abc import Callable

import pytest
from rich.console import Console
from rich.text import Text
from textual import events
from textual.widgets import Button, Input, Select

from tui.app import ConsoleApp
from tui.fake import FakeSystem
from tui.keymap import ACTIONS, KEY_NAMES, MAP_KEYS
from tui.snapshot import CommandResult
from tui.widgets import FaultDialog, HelpScreen, MapView, MessageLog
from tui.widgets.supervision_tree import SupervisionTree

KEYS = {"enter": "\r", "space": " ", "right_square_bracket": "]", "left_square_bracket": "[",
        "question_mark": "?", "escape": "\x1b", "slash": "/"}
TIMEOUT_S = 10.0


def press(app: ConsoleApp, key: str) -> None:
    """Post a key event the way the terminal driver would."""
    app.post_message(events.Key(key, KEYS.get(key, key if len(key) == 1 else None)))


async def until(cond: Callable[[], object], what: str, timeout: float = TIMEOUT_S) -> None:
    """Poll ``cond`` every 20 ms (wall) until true."""
    loop = asyncio.get_running_loop()
    deadline = loop.time() + timeout
    while not cond():
        if loop.time() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        await asyncio.sleep(0.02)


def drive(test, *, speed: float | None = None, size=(120, 40), **app_kw) -> ConsoleApp:
    """Run ``await test(app, fake)`` inside ``App.run_test`` on a fresh asyncio loop."""
    fake = FakeSystem(speed=speed, seed=3)
    app = ConsoleApp(fake, **app_kw)

    async def main():
        async with app.run_test(size=size, notifications=True):
            await until(lambda: app.snapshot is not None, "the first snapshot")
            await test(app, fake)

    asyncio.run(main())
    return app


def calls(fake: FakeSystem, name: str) -> list[tuple]:
    return [args for method, args in fake.calls if method == name]


def plain(renderable, width: int = 60) -> str:
    """What a Rich renderable looks like as text."""
    console = Console(width=width, record=True, file=io.StringIO())
    console.print(renderable)
    return console.export_text()


def tree_text(app: ConsoleApp) -> str:
    return str(app.query_one(SupervisionTree).content)


def notes(app: ConsoleApp) -> list[str]:
    return [f"{n.title}: {n.message}" for n in app._notifications]


def test_start_mapping_key_reaches_the_controller_and_phase_shows():
    """'m' calls start_mapping and the game panel shows the mapping phase."""

    async def test(app, fake):
        press(app, "m")
        await until(lambda: calls(fake, "start_mapping"), "start_mapping call")
        await until(lambda: "phase mapping" in plain(app.game_panel.content), "panel phase")
        await until(lambda: (app.snapshot.map.cells != -1).any(), "map cells known")

    drive(test, speed=4.0)


def test_wrong_phase_confirm_notifies_instead_of_calling():
    """Enter in phase idle calls nothing and shows a warning notification."""

    async def test(app, fake):
        press(app, "enter")
        await until(lambda: any("nothing to choose" in n for n in notes(app)), "notification")
        assert not calls(fake, "hide_at") and not calls(fake, "seek_at")

    drive(test, speed=1.0)


def test_hide_and_seek_with_the_cursor():
    """After mapping, arrows move the cursor and Enter hides there; Enter again seeks there."""

    async def test(app, fake):
        press(app, "m")
        await until(lambda: app.snapshot.phase == "map_ready", "map ready", timeout=20)
        view = app.query_one(MapView)
        view.cursor = (150.0, 130.0)
        press(app, "left")
        await until(lambda: view.cursor[0] < 150.0, "cursor moved")
        x, y = view.cursor
        press(app, "r")
        await until(lambda: view.cursor_heading == 135.0, "heading rotated")
        press(app, "enter")
        await until(lambda: calls(fake, "hide_at"), "hide_at call")
        assert calls(fake, "hide_at")[0] == (x, y, 135.0)
        await until(lambda: app.snapshot.phase == "hidden", "hidden", timeout=20)
        assert app.snapshot.hide_spot is not None
        press(app, "enter")
        await until(lambda: calls(fake, "seek_at") == [(x, y)], "seek_at call")
        await until(lambda: app.snapshot.phase == "found", "found", timeout=20)

    drive(test, speed=None)


def test_w_asks_for_a_wider_search_at_the_cursor():
    """'w' once hidden seeks at the cursor with a 120 cm wider search; before that it only
    warns."""

    async def test(app, fake):
        press(app, "w")
        await until(lambda: any("wider search" in n for n in notes(app)), "warning")
        assert not calls(fake, "seek_at")
        press(app, "m")
        await until(lambda: app.snapshot.phase == "map_ready", "map ready", timeout=20)
        view = app.query_one(MapView)
        view.cursor = (150.0, 130.0)
        press(app, "enter")
        await until(lambda: app.snapshot.phase == "hidden", "hidden", timeout=20)
        press(app, "w")
        await until(lambda: calls(fake, "seek_at") == [(150.0, 130.0, 120.0)], "seek_at call")

    drive(test, speed=None)


def test_refusal_shows_as_a_notification():
    """A refused command arrives as a warning notification with the system's reason."""

    async def test(app, fake):
        press(app, "x")  # stop mapping while idle
        await until(lambda: any("stop mapping: refused" in n for n in notes(app)), "refusal")
        assert CommandResult("stop_mapping", "refused",
                             "stop mapping is valid in mapping, not in idle") in app.results

    drive(test, speed=1.0)


def test_pause_resume_and_speed_keys():
    """Space pauses (and resumes); ']' steps the speed x1 -> x4; the panel shows it."""

    async def test(app, fake):
        press(app, "space")
        await until(lambda: app.snapshot.paused, "paused")
        t = app.snapshot.time_s
        await asyncio.sleep(0.3)
        assert app.snapshot.time_s == t  # simulated time stands still
        press(app, "space")
        await until(lambda: not app.snapshot.paused, "resumed")
        press(app, "right_square_bracket")
        await until(lambda: app.snapshot.speed == 4.0, "x4")
        press(app, "left_square_bracket")
        await until(lambda: app.snapshot.speed == 1.0, "x1")
        assert calls(fake, "set_speed") == [(4.0,), (1.0,)]

    drive(test, speed=1.0)


def test_speed_keys_pressed_quickly_step_from_the_speed_asked_last():
    """']' three times before a snapshot shows the first: x1 -> x4 -> x16 -> max."""

    async def test(app, fake):
        for _ in range(3):
            press(app, "right_square_bracket")
        await until(lambda: len(calls(fake, "set_speed")) == 3, "three speed calls")
        assert calls(fake, "set_speed") == [(4.0,), (16.0,), (None,)]
        await until(lambda: app.snapshot.speed is None, "max speed shown")

    drive(test, speed=1.0)


def test_speed_keys_at_either_end_change_nothing():
    """'[' at x1 and ']' at "as fast as possible" send no speed change (nothing to log)."""

    async def test(app, fake):
        press(app, "left_square_bracket")
        await asyncio.sleep(0.3)
        assert calls(fake, "set_speed") == []
        for _ in range(3):
            press(app, "right_square_bracket")
        await until(lambda: app.snapshot.speed is None, "max speed shown")
        press(app, "right_square_bracket")
        await asyncio.sleep(0.3)
        assert calls(fake, "set_speed") == [(4.0,), (16.0,), (None,)]

    drive(test, speed=1.0)


async def inject_from_dialog(app: ConsoleApp, target: str, kind: str) -> None:
    """Open the fault dialog (f), choose ``target`` and ``kind``, press Inject."""
    press(app, "f")
    await until(lambda: isinstance(app.screen, FaultDialog)
                and app.screen.query(Select)
                and all(w.is_mounted for w in app.screen.query(Select)), "fault dialog")
    dialog = app.screen
    dialog.query_one("#target", Select).value = target
    await until(lambda: len(dialog.query_one("#kind", Select)._options) > 1, "kinds")
    dialog.query_one("#kind", Select).value = kind
    dialog.query_one("#inject", Button).press()


def test_fault_dialog_injects_a_crash_that_flashes_and_recovers():
    """f opens the dialog; a crash on mapper/lidar shows restarting, then ↻1."""

    async def test(app, fake):
        press(app, "3")
        await inject_from_dialog(app, "mapper/lidar", "crash")
        await until(lambda: calls(fake, "inject_fault"), "inject call")
        assert calls(fake, "inject_fault")[0] == ("mapper/lidar", "crash", None, {})
        await until(lambda: "lidar restarting" in tree_text(app), "restarting shown")
        await until(lambda: "lidar running ↻1" in tree_text(app), "recovered")
        await until(lambda: any(e.kind == "crash" for e in app.snapshot.timeline), "timeline")

    drive(test, speed=1.0)


def test_fault_dialog_rejects_a_bad_duration():
    """A non-numeric duration is an inline error, nothing is injected."""

    async def test(app, fake):
        press(app, "f")
        await until(lambda: isinstance(app.screen, FaultDialog)
                    and app.screen.query(Select)
                    and all(w.is_mounted for w in app.screen.query(Select)), "fault dialog")
        dialog = app.screen
        dialog.query_one("#target", Select).value = "mapper.lidar"
        await until(lambda: len(dialog.query_one("#kind", Select)._options) > 1, "kinds")
        dialog.query_one("#kind", Select).value = "dead"
        dialog.query_one("#duration", Input).value = "soon"
        dialog.query_one("#inject", Button).press()
        await until(lambda: "duration must be a number" in str(
            dialog.query_one("#error").content), "inline error")
        assert not calls(fake, "inject_fault")
        press(app, "escape")
        await until(lambda: not isinstance(app.screen, FaultDialog), "dialog closed")

    drive(test, speed=1.0)


def test_log_filter_and_pause():
    """The log shows decoded lines; a filter keeps only matching ones; p pauses it."""

    async def test(app, fake):
        press(app, "m")
        press(app, "2")
        log = app.query_one(MessageLog)
        await until(lambda: any("LIDAR_SAMPLE" in t for t in log.shown_text()), "lidar lines")
        app.query_one("#log-filter", Input).value = "motor"
        await until(lambda: log.shown_text() and all("motor" in t for t in log.shown_text()),
                    "filtered")
        press(app, "escape")
        press(app, "p")
        await until(lambda: log.paused, "log paused")
        n = len(log.shown_text())
        seq = log.last_seq
        await until(lambda: log.last_seq > seq, "more lines collected")
        assert len(log.shown_text()) == n
        press(app, "p")
        await until(lambda: len(log.shown_text()) > n, "resumed lines")

    drive(test, speed=4.0)


def test_truth_toggle_and_zoom_change_the_map_title():
    """g overlays ground truth, '-' zooms out: both show in the map's title."""

    async def test(app, fake):
        view = app.query_one(MapView)
        await until(lambda: "cm/px" in str(view.border_title), "title")
        before = view.scale
        press(app, "g")
        await until(lambda: "truth" in str(view.border_title), "truth in title")
        press(app, "minus")
        await until(lambda: view.scale > before, "zoomed out")

    drive(test, speed=1.0)


@pytest.mark.parametrize(("size", "legend"), [
    ((120, 40), "truth: ■ unseen ■ missed ■ false ○ true pose"),
    ((80, 24), "■unseen ■missed ■false ○true"),
])
def test_truth_legend_is_whole_in_the_map_title_at_120_and_80_columns(size, legend):
    """The overlay's legend fits the top border: in words at 120 columns, short at 80."""

    async def test(app, fake):
        view = app.query_one(MapView)
        press(app, "g")
        await until(lambda: "■" in str(view.border_title), "legend in title")
        title = Text.from_markup(str(view.border_title)).plain
        assert title.endswith(legend)
        assert len(title) <= view.size.width - 4

    drive(test, speed=1.0, size=size)


def test_map_draws_rovers_and_occupied_cells():
    """The rendered map holds the rover glyphs and light (occupied) pixels once mapped."""

    async def test(app, fake):
        press(app, "m")
        view = app.query_one(MapView)
        await until(lambda: app.snapshot.phase == "map_ready", "mapped", timeout=20)
        await asyncio.sleep(0.2)
        text = "".join(view.render_line(y).text for y in range(view.size.height))
        assert any(ch in text for ch in "→↗↑↖←↙↓↘")
        classes = view.pixel_classes()
        assert (classes == 2).any() and (classes == 1).any()

    drive(test, speed=None)


def test_export_key_saves_into_the_export_dir(tmp_path):
    """e exports the map to the directory given to the app and notifies the path."""

    async def test(app, fake):
        press(app, "m")
        await until(lambda: (app.snapshot.map.cells != -1).any(), "some map")
        press(app, "e")
        await until(lambda: (tmp_path / "map.pgm").exists(), "map.pgm")
        await until(lambda: any("map.pgm" in n for n in notes(app)), "notification")

    drive(test, speed=4.0, export_dir=str(tmp_path))


def test_help_screen_lists_every_action():
    """? opens the help with a line per row of the action table (its key as people read
    it, its help text) and one per map key, nothing else; escape closes it."""

    async def test(app, fake):
        press(app, "question_mark")
        await until(lambda: isinstance(app.screen, HelpScreen), "help")
        rows = list(app.screen.keys)
        assert len(rows) == len(ACTIONS) + len(MAP_KEYS)
        for a in ACTIONS:
            assert (KEY_NAMES.get(a.key, a.key), a.help) in rows, a
        for row in MAP_KEYS:
            assert row in rows
        press(app, "escape")
        await until(lambda: not isinstance(app.screen, HelpScreen), "help closed")

    drive(test, speed=1.0)


def test_command_palette_offers_every_action():
    """The palette has one command per row of the action table, but quit (ctrl+c and q
    stay keys): titled with its help text (up to a colon), its key as the help."""

    async def test(app, fake):
        ours = [c for c in app.get_system_commands(app.screen) if c.help.startswith("key ")]
        offered = [a for a in ACTIONS if a.action != "quit"]
        assert len(ours) == len(offered)
        for a, command in zip(offered, ours, strict=True):
            assert a.help.startswith(command.title) and command.title, (a, command.title)
            assert command.help == f"key {KEY_NAMES.get(a.key, a.key)}"

    drive(test, speed=1.0)


@pytest.mark.parametrize("size", [(120, 40), (80, 24)], ids=["120x40", "80x24"])
def test_layout_fits_both_terminal_sizes(size):
    """Every panel has room at 120x40 and 80x24 (no zero-sized or clipped widgets)."""

    async def test(app, fake):
        def laid_out() -> bool:
            return all(app.query_one(s).region.width >= 20 and app.query_one(s).region.height >= 5
                       for s in ("#map", "#game", "#tabs"))

        await until(laid_out, "every panel laid out with room")
        for selector in ("#map", "#game", "#tabs"):
            region = app.query_one(selector).region
            assert region.right <= size[0] and region.bottom <= size[1] - 1, (selector, region)

    drive(test, speed=1.0, size=size)


def test_quit_key_stops_trio_and_returns_zero():
    """q cancels the guest run, waits for it, and the app returns status 0."""
    holder = {}

    async def test(app, fake):
        holder["guest"] = app._guest
        press(app, "q")
        await until(lambda: app.return_value == 0, "exit status")

    app = drive(test, speed=1.0)
    assert app.return_value == 0
    assert holder["guest"].finished and app.system_error is None


def test_system_crash_is_a_notification_not_a_traceback():
    """When the system's run raises, the app stays up and shows the error."""

    class Broken(FakeSystem):
        async def run(self, publish, requests):
            await requests.receive()
            publish(self.snapshot())
            raise RuntimeError("boom")

    app = ConsoleApp(Broken(speed=1.0))

    async def main():
        async with app.run_test(size=(120, 40), notifications=True):
            await until(lambda: app.system_error is not None, "system error")
            await until(lambda: any("boom" in n for n in notes(app)), "notification")

    asyncio.run(main())
    assert isinstance(app.system_error, RuntimeError)


def footer_labels(app: ConsoleApp) -> dict[str, tuple[str, bool]]:
    """Key -> (footer label, enabled) as the footer shows them now."""
    return {key: (b.binding.description, b.enabled)
            for key, b in app.screen.active_bindings.items()}


def test_footer_says_resume_while_paused():
    async def test(app, fake):
        await until(lambda: footer_labels(app).get("space", ("",))[0] == "Pause", "Pause")
        press(app, "space")
        await until(lambda: app.snapshot.paused, "paused")
        await until(lambda: footer_labels(app)["space"][0] == "Resume", "Resume shown")
        press(app, "space")
        await until(lambda: not app.snapshot.paused, "resumed")

    drive(test, speed=1.0)


def test_keys_the_system_refuses_are_greyed():
    class RealTime(FakeSystem):
        def snapshot(self, now_s=None):
            return dataclasses.replace(super().snapshot(now_s),
                                       refused=("pause", "resume", "set_speed"))

    app = ConsoleApp(RealTime(speed=1.0, seed=3))

    async def main():
        async with app.run_test(size=(120, 40)):
            await until(lambda: app.snapshot is not None and app.snapshot.refused, "snapshot")
            await until(lambda: footer_labels(app)["space"] == ("Pause", False), "greyed")
            assert footer_labels(app)["right_square_bracket"][1] is False
            assert footer_labels(app)["m"][1] is True

    asyncio.run(main())


def test_screenshot_key_saves_an_svg_into_the_export_dir(tmp_path):
    async def test(app, fake):
        press(app, "s")
        await until(lambda: list(tmp_path.glob("*.svg")), "svg written")
        await until(lambda: any("screenshot saved" in n and str(tmp_path) in n
                                for n in notes(app)), "says where")

    drive(test, speed=1.0, export_dir=str(tmp_path))


def test_screenshot_into_a_missing_folder_is_a_notification(tmp_path):
    async def test(app, fake):
        press(app, "s")
        await until(lambda: any("screenshot: error" in n for n in notes(app)), "error shown")

    drive(test, speed=1.0, export_dir=str(tmp_path / "missing"))
