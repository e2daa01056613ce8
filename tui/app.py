"""The console app: watch, steer and break a game from a Textual UI.

The app is given a `tui.snapshot.System` and knows nothing else about it. On
mount it starts the system's Trio side as a guest run on Textual's asyncio
loop (`tui.guest.TrioGuest`), in one thread. About `REFRESH_HZ` times per wall
second it asks the system for a snapshot (one request at a time, so a slow
screen never piles work up) and redraws from it; key bindings call the
system's `Controller` methods, which only queue the command; results come back
as `CommandResult` and refusals and errors show as notifications.

Every action is one row of `tui.keymap.ACTIONS`: its key binding, footer label,
help text and command palette entry all come from that row. How often frames
are drawn is `tui.pacing`.

Quitting (``q``, ``ctrl+c``, or any other way the app ends) cancels Trio's
root scope and waits for the guest run to finish before the asyncio loop
closes, so the process exits with status 0 and no traceback.
"""

from __future__ import annotations

import asyncio
import functools
import gc
import pathlib
from collections.abc import Iterable

import outcome
import trio
from textual.app import App, ComposeResult, SystemCommand
from textual.binding import Binding
from textual.containers import Horizontal, Vertical, VerticalScroll
from textual.message import Message
from textual.screen import Screen
from textual.widgets import Footer, Input, TabbedContent, TabPane

from tui.guest import TrioGuest, quit_on_signals
from tui.keymap import (
    ACTION_COMMANDS,
    ACTIONS,
    KEY_NAMES,
    MAP_KEYS,
    SPEEDS,
    WIDER_SEARCH_CM,
    UiAction,
    nearest_speed,
)
from tui.pacing import REFRESH_HZ, FramePacer
from tui.screenshot import save_screenshot
from tui.snapshot import CommandResult, Snapshot, System
from tui.widgets import (
    FaultDialog,
    FaultRequest,
    GamePanel,
    HelpScreen,
    MapView,
    MessageLog,
    QueueTable,
    SupervisionTree,
    Timeline,
)

__all__ = ["ConsoleApp"]

#: The queue table and the tree are redrawn on every this many snapshots.
TABLE_EVERY = 3


def _has_os_error(exc: BaseException) -> bool:
    if isinstance(exc, BaseExceptionGroup):
        return any(_has_os_error(e) for e in exc.exceptions)
    return isinstance(exc, OSError)


class ConsoleApp(App[int]):
    """The hideseek console for one `System`.

    Args:
        system: the system to run and show (`tui.fake.FakeSystem` or the real one).
        export_dir: where ``export map`` saves files.
        refresh_hz: snapshots asked for per wall second.
    """

    TITLE = "hideseek"
    CSS = """
    #main { height: 1fr; }
    MapView { width: 1fr; }
    #side { width: 42%; min-width: 38; }
    TabbedContent { height: 1fr; }
    TabPane { padding: 0; }
    #tree-scroll, #queue-scroll { height: 1fr; }
    """
    BINDINGS = [
        Binding(a.key, a.action, a.label, show=a.footer, key_display=KEY_NAMES.get(a.key))
        for a in ACTIONS
    ] + [
        Binding("ctrl+c", "quit", "Quit", show=False, priority=True),
        Binding("escape", "focus_map", "Map", show=False),
    ]

    actions: tuple[UiAction, ...] = ACTIONS
    """The actions the help screen and the command palette list (a subclass with other
    bindings names its own)."""
    speeds: tuple[float | None, ...] = SPEEDS
    """The speed steps of ``]`` and ``[`` (None: as fast as possible)."""

    class SnapshotArrived(Message):
        """The system published a snapshot (posted from Trio)."""

        def __init__(self, snapshot: Snapshot) -> None:
            super().__init__()
            self.snapshot = snapshot

    class ResultArrived(Message):
        """The system published a command result (posted from Trio)."""

        def __init__(self, result: CommandResult) -> None:
            super().__init__()
            self.result = result

    class SystemEnded(Message):
        """The system's Trio run ended."""

        def __init__(self, result: outcome.Outcome) -> None:
            super().__init__()
            self.result = result

    def __init__(self, system: System, *, export_dir: str = ".",
                 refresh_hz: float = REFRESH_HZ) -> None:
        super().__init__()
        if not refresh_hz > 0:
            raise ValueError(f"refresh_hz must be > 0, got {refresh_hz!r}")
        self.system = system
        self.export_dir = export_dir
        self.refresh_hz = refresh_hz
        self.snapshot: Snapshot | None = None
        """The newest snapshot shown."""
        self.results: list[CommandResult] = []
        """Command results received, newest last (bounded)."""
        self.system_error: BaseException | None = None
        """Why the system's run failed, if it did."""
        self.stopped_by_signal = False
        """SIGINT or SIGTERM quit the console (the command prints `tui.stopping`'s line)."""
        self.snapshots_shown = 0
        self._guest = TrioGuest(on_done=lambda r: self.post_message(self.SystemEnded(r)))
        self._requests: trio.MemorySendChannel[None] | None = None
        self._awaiting = 0  # ticks since the outstanding request, 0 = none outstanding
        self._pacer = FramePacer(refresh_hz)
        self._panel_phase = ""  # phase the game panel shows
        self._asked_speed: tuple[int, int] | None = None  # (speeds index, snapshots_shown)
        # Held, not queried: App.query_one searches the *current* screen, which is a
        # dialog while one is open, and snapshots keep arriving then.
        self.map_view = MapView(id="map")
        self.game_panel = GamePanel(id="game")
        self.queue_table = QueueTable(id="queue-table")
        self.message_log = MessageLog(id="message-log")
        self.tree_view = SupervisionTree(id="tree-view")
        self.timeline = Timeline(id="timeline")
        self.tabs = TabbedContent(id="tabs")

    def compose(self) -> ComposeResult:
        with Horizontal(id="main"):
            yield self.map_view
            with Vertical(id="side"):
                yield self.game_panel
                with self.tabs:
                    with TabPane("Queues", id="queues"):
                        with VerticalScroll(id="queue-scroll"):
                            yield self.queue_table
                    with TabPane("Log", id="log"):
                        yield self.message_log
                    with TabPane("Tree", id="tree"):
                        with VerticalScroll(id="tree-scroll"):
                            yield self.tree_view
                    with TabPane("Events", id="events"):
                        yield self.timeline
        yield Footer(compact=True)

    # -- Trio side -------------------------------------------------------------
    def on_mount(self) -> None:
        self.map_view.focus()
        self._guest.start(self._trio_main, clock=self.system.clock)
        self.set_interval(1.0 / self.refresh_hz, self._tick)
        self._signals = quit_on_signals(self._quit_on_signal)

    def _quit_on_signal(self) -> None:
        self.stopped_by_signal = True
        self.call_next(self.action_quit)

    def _remove_signal_handlers(self) -> None:
        loop = asyncio.get_running_loop()
        for sig in getattr(self, "_signals", ()):
            loop.remove_signal_handler(sig)
        self._signals = ()

    async def _trio_main(self) -> None:
        send, receive = trio.open_memory_channel[None](1)
        self._requests = send
        async with send, receive:
            await self.system.run(self._publish, receive)

    def _publish(self, item: Snapshot | CommandResult) -> None:
        """Given to the system: called from Trio, same thread; never blocks."""
        if isinstance(item, Snapshot):
            self.post_message(self.SnapshotArrived(item))
        elif isinstance(item, CommandResult):
            self.post_message(self.ResultArrived(item))
        else:
            raise TypeError(f"publish takes a Snapshot or a CommandResult, "
                            f"got {type(item).__name__}")

    def _tick(self) -> None:
        """Ask for the next snapshot unless one is still on its way (or build it here,
        for a system that offers ``host_snapshot``)."""
        if self._requests is None or self._guest.finished:
            return
        host_snapshot = getattr(self.system, "host_snapshot", None)
        if host_snapshot is not None:
            if self._skip_frame():
                return
            try:
                snap = host_snapshot()
            except Exception as exc:  # a bug in a snapshot must not kill the UI
                self.notify(f"{type(exc).__name__}: {exc}", title="snapshot", severity="error")
                return
            self.on_console_app_snapshot_arrived(self.SnapshotArrived(snap))
            return
        if self._awaiting and self._awaiting < 2 * self.refresh_hz:
            self._awaiting += 1
            return
        if self._skip_frame():
            return
        try:
            self._requests.send_nowait(None)
        except (trio.WouldBlock, trio.ClosedResourceError, trio.BrokenResourceError):
            pass
        self._awaiting = 1

    def _skip_frame(self) -> bool:
        """At "as fast as possible", fewer frames (see `tui.pacing.FramePacer`)."""
        snap = self.snapshot
        if snap is None or snap.speed is not None or snap.paused:
            return False
        return self._pacer.skip(self._guest.busy_s)

    async def on_unmount(self) -> None:
        self._remove_signal_handlers()
        await self._guest.stop()

    # -- from the system -----------------------------------------------------
    def on_console_app_snapshot_arrived(self, message: SnapshotArrived) -> None:
        self._awaiting = 0
        if self.snapshot is None:
            # The app and the system are built: move every object made so far out of
            # the collector's sight, so each full collection walks only what came
            # after (it walked the whole UI and system, ~3% of the simulation's time).
            gc.freeze()
        self.show(message.snapshot)

    def on_console_app_result_arrived(self, message: ResultArrived) -> None:
        result = message.result
        self.results.append(result)
        del self.results[:-100]
        title = result.command.replace("_", " ")
        if result.status == "refused":
            self.notify(result.reason or "refused", title=f"{title}: refused",
                        severity="warning")
        elif result.status == "error":
            self.notify(result.reason or "failed", title=f"{title}: error", severity="error")
        elif result.reason:
            self.notify(result.reason, title=title, timeout=3)

    def on_console_app_system_ended(self, message: SystemEnded) -> None:
        result = message.result
        if isinstance(result, outcome.Error):
            self.system_error = result.error
            if _has_os_error(result.error):  # the system could not open a port or device:
                self.exit(1)  # the command prints it as one line
                return
            self.notify(f"{type(result.error).__name__}: {result.error}",
                        title="the system stopped", severity="error", timeout=30)
        elif getattr(self.system, "auto", False):
            self.exit(0)  # an auto game ended by itself: the command prints its report

    def show(self, snap: Snapshot) -> None:
        """Redraw every panel from a snapshot."""
        old = self.snapshot
        self.snapshot = snap
        if old is None or (old.paused, old.refused) != (snap.paused, snap.refused):
            self.refresh_bindings()  # Pause / Resume, greyed keys
        if not (self.map_view.is_attached and self.message_log.is_mounted):
            return  # before compose finished, or after the screen went away
        self.snapshots_shown += 1
        self.map_view.update_snapshot(snap)
        # The panel beside the map widens every repaint to the whole screen width:
        # redraw it on every other frame (and at once when the phase changes).
        if self.snapshots_shown % 2 == 0 or snap.phase != self._panel_phase:
            self.game_panel.update_snapshot(snap)
            self._panel_phase = snap.phase
        self.message_log.add_lines(snap.log)
        self.timeline.add_events(snap.timeline)
        self._show_tab(snap)

    def _show_tab(self, snap: Snapshot, force: bool = False) -> None:
        """Redraw the panels that are only drawn while their tab is shown (they cost)."""
        tab = self.tabs.active
        self.message_log.live = tab == "log"
        self.timeline.live = tab == "events"
        if self.timeline.live:
            self.timeline.flush()
        # Tables change little between frames and cost a lot to draw: a third of the rate.
        if self.snapshots_shown % TABLE_EVERY and not force:
            return
        if tab == "queues":
            self.queue_table.update_queues(snap.queues)
        elif tab == "tree":
            self.tree_view.update_tree(snap.tree, snap.time_s)

    def on_tabbed_content_tab_activated(self, event: TabbedContent.TabActivated) -> None:
        if self.snapshot is not None and self.map_view.is_attached:
            self._show_tab(self.snapshot, force=True)

    # -- actions -----------------------------------------------------------------
    def _call(self, method: str, *args: object) -> None:
        """Call a controller method; a failure is a notification, never a traceback."""
        try:
            getattr(self.system, method)(*args)
        except Exception as exc:  # the contract says never raise; a bug must not kill the UI
            self.notify(f"{type(exc).__name__}: {exc}", title=method, severity="error")

    def action_start_mapping(self) -> None:
        self._call("start_mapping")

    def action_stop_mapping(self) -> None:
        self._call("stop_mapping")

    def action_new_game(self) -> None:
        self._call("new_game")

    def action_confirm(self) -> None:
        """Enter on the map: the hide spot or a seek guess, by phase."""
        phase = self.snapshot.phase if self.snapshot else "idle"
        view = self.map_view
        x, y = view.cursor
        if phase == "map_ready":
            self._call("hide_at", x, y, view.cursor_heading)
        elif phase in ("hidden", "not_found"):
            self._call("seek_at", x, y)
        else:
            self.notify(f"nothing to choose in phase {phase.replace('_', ' ')}: the cursor "
                        "picks the hide spot when the map is ready, and seek guesses once "
                        "hidden", severity="warning")

    def action_wider_search(self) -> None:
        """``w`` on the map: seek at the cursor, searching `WIDER_SEARCH_CM` round it (after
        a guess there came back not found: the seeker's or the hider's dead reckoning may
        be that far off)."""
        phase = self.snapshot.phase if self.snapshot else "idle"
        if phase not in ("hidden", "not_found"):
            self.notify(f"a wider search is a seek guess: not in phase {phase.replace('_', ' ')}",
                        severity="warning")
            return
        x, y = self.map_view.cursor
        self._call("seek_at", x, y, WIDER_SEARCH_CM)

    def action_toggle_pause(self) -> None:
        if self.snapshot is not None and self.snapshot.paused:
            self._call("resume")
        else:
            self._call("pause")

    def action_pause(self) -> None:
        self._call("pause")

    def action_resume(self) -> None:
        self._call("resume")

    def check_action(self, action: str, parameters: tuple[object, ...]) -> bool | None:
        """Footer and keys follow the state: ``space`` is Pause or Resume; keys whose
        commands the system refuses whatever the phase are greyed (None: shown, not run)."""
        snap = self.snapshot
        if snap is None:
            return True
        if action == "pause" and snap.paused:
            return False
        if action == "resume" and not snap.paused:
            return False
        commands = ACTION_COMMANDS.get(action, ())
        if commands and all(c in snap.refused for c in commands):
            return None
        return True

    def action_screenshot(self, filename: str | None = None, path: str | None = None) -> None:
        """Save an SVG of the screen (and a PNG where cairosvg is installed) into ``path``
        (the export directory by default) and say where."""
        folder = pathlib.Path(path or self.export_dir).expanduser().resolve()
        try:
            saved = save_screenshot(self, filename, folder)
        except OSError as exc:
            self.notify(str(exc), title="screenshot: error", severity="error")
            return
        self.notify(", ".join(saved), title="screenshot saved", timeout=5)

    def _speed_index(self) -> int:
        asked = self._asked_speed
        if asked is not None and self.snapshots_shown - asked[1] < 3:
            return asked[0]  # a key pressed again before a snapshot showed the last one
        return nearest_speed(self.speeds, self.snapshot.speed if self.snapshot else 1.0)

    def action_faster(self) -> None:
        self._step_speed(+1)

    def action_slower(self) -> None:
        self._step_speed(-1)

    def _step_speed(self, step: int) -> None:
        """One speed step; at either end a note instead of a speed "change" to the same."""
        now = self._speed_index()
        index = min(len(self.speeds) - 1, max(0, now + step))
        if index == now:
            self.notify("already as fast as possible" if step > 0 else "already at x1",
                        timeout=2)
            return
        self._set_speed(index)

    def _set_speed(self, index: int) -> None:
        self._asked_speed = (index, self.snapshots_shown)
        self._call("set_speed", self.speeds[index])  # the result (or refusal) is the notification

    def action_toggle_truth(self) -> None:
        view = self.map_view
        if self.snapshot is not None and self.snapshot.truth is None:
            self.notify("no ground truth: this room is real", severity="warning")
            return
        view.toggle_truth()

    def action_export_map(self) -> None:
        self._call("export_map", self.export_dir)

    def action_record(self) -> None:
        """``R``: start or stop recording, where the system can record (the live one)."""
        if not hasattr(self.system, "record"):
            self.notify("this system cannot be recorded", severity="warning")
            return
        self._call("record", str(self.export_dir))

    def action_faults(self) -> None:
        snap = self.snapshot
        if snap is None or not snap.catalogue:
            self.notify("the system offers no faults (yet)", severity="warning")
            return
        self.push_screen(FaultDialog(snap.catalogue, snap.faults), self._fault_chosen)

    def _fault_chosen(self, request: FaultRequest | None) -> None:
        if request is None:
            return
        if request.action == "inject":
            self._call("inject_fault", request.target, request.kind, request.duration_s,
                       request.params)
        elif request.target == "*":
            for fault in self.snapshot.faults if self.snapshot else ():
                self._call("clear_fault", fault.id)
        else:
            self._call("clear_fault", request.target)

    def action_toggle_log_pause(self) -> None:
        log = self.message_log
        log.paused = not log.paused
        self.notify("log paused" if log.paused else "log resumed", timeout=1.5)

    def action_filter_log(self) -> None:
        self.action_tab("log")
        self.message_log.query_one("#log-filter", Input).focus()

    def action_tab(self, tab: str) -> None:
        self.tabs.active = tab

    def action_focus_map(self) -> None:
        self.map_view.focus()

    def action_help(self) -> None:
        keys = [(KEY_NAMES.get(a.key, a.key), a.help) for a in self.actions] + list(MAP_KEYS)
        self.push_screen(HelpScreen(keys, intro="[b]hideseek console[/b]: keys\n"))

    async def action_quit(self) -> None:
        """Stop the system's Trio run, then exit with status 0."""
        await self._guest.stop()
        self.exit(0)

    def get_system_commands(self, screen: Screen) -> Iterable[SystemCommand]:
        for command in super().get_system_commands(screen):
            if command.title != "Screenshot":  # Textual's writes to ~/Downloads: ours below
                yield command
        for a in self.actions:
            if a.action in ("quit",):
                continue
            yield SystemCommand(a.help.split(":")[0], f"key {KEY_NAMES.get(a.key, a.key)}",
                                functools.partial(self.run_action, a.action))
