"""A serial rover survives its cable: unplugged and replugged on real pseudo-terminals.

The cable is two pty pairs joined by a relay, as in ``tests/test_remote.py``:
the server opens one pair's slave, the rover (`supervisors.remote`, what
``hideseek rover --link serial:...`` runs) the other's, each through a symlink
the test owns, as udev's names are. Unplugging closes the relay's ends and
both retained slaves (the kernel hangs up the ports the server and the rover
hold) and removes the symlinks; replugging makes new pty pairs, which the
kernel names as it likes, and points the symlinks at them.
"""

from __future__ import annotations

import os
import pathlib
import tty

import trio
import trio.testing

from server.links import parse_link
from server.store import Store
from supervisors.harness.headless import Budget, GameReport, play_game
from supervisors.remote import open_remote_rover
from supervisors.system import open_sim_system
from tui.serve_console import format_status
from world.scenario import load_scenario

PTY_CLOCK_THRESHOLD_S = 0.0005  # real time with nothing to do before the clock jumps [s]
UNPLUGGED_S = 2.0  # [s]


def _link(target: str, path: pathlib.Path) -> None:
    """Point the symlink ``path`` at ``target`` in one step (as udev replaces a name)."""
    tmp = path.with_name(path.name + ".new")
    os.symlink(target, tmp)
    os.replace(tmp, path)


class Cable:
    """Two pty pairs and a relay: the server's adapter and the rover's, joined.

    ``server_names`` and ``rover_names``: for each plugging, the kernel-like
    names (symlinks in ``folder``) the two adapters appear under; ``stable`` maps
    a by-id-like name to follow them (None: the kernel name is the one given).
    """

    def __init__(self, folder: pathlib.Path) -> None:
        self.folder = folder
        self.plugged = 0
        self._fds: list[int] = []
        self._names: list[pathlib.Path] = []

    async def plug(self, nursery: trio.Nursery, server_name: str, rover_name: str,
                   stable: dict[str, str] | None = None) -> None:
        """New pty pairs under these names, relayed both ways in ``nursery``."""
        ends = []
        for name in (server_name, rover_name):
            master, slave = os.openpty()
            tty.setraw(slave)
            self._fds += [slave]
            path = self.folder / name
            _link(os.ttyname(slave), path)
            self._names.append(path)
            ends.append(trio.lowlevel.FdStream(master))
        for by_id, name in (stable or {}).items():
            _link(str(self.folder / name), self.folder / by_id)
            self._names.append(self.folder / by_id)
        self._scope = trio.CancelScope()
        self._ends = ends
        nursery.start_soon(self._relay_both, ends[0], ends[1])
        self.plugged += 1

    async def _relay_both(self, a, b) -> None:
        with self._scope:
            async with trio.open_nursery() as relay:
                relay.start_soon(_relay, a, b)
                relay.start_soon(_relay, b, a)

    async def unplug(self) -> None:
        """Close every end (the ports hang up) and remove the names."""
        self._scope.cancel()
        for end in self._ends:
            await end.aclose()
        for fd in self._fds:
            os.close(fd)
        for path in self._names:
            path.unlink(missing_ok=True)
        self._fds, self._names, self._ends = [], [], []


async def _relay(a, b) -> None:
    try:
        while data := await a.receive_some(4096):
            await b.send_all(data)
    except (OSError, trio.BrokenResourceError, trio.ClosedResourceError):
        return


def _game_with_unplugs(tmp_path: pathlib.Path, *, unplugs: int, renamed: bool) -> dict:
    """A whole game, the mapper on the cable; the cable unplugged ``unplugs`` times for
    `UNPLUGGED_S` while the mapper maps. ``renamed``: the adapters come back under new
    kernel names, the server and the rover open stable by-id names that follow them."""
    scenario = load_scenario("empty")
    report = GameReport(scenario.name, 1)
    seen: dict = {"report": report, "events": []}
    server_port = "by-id-server" if renamed else "ttyUSB0"
    rover_port = "by-id-rover" if renamed else "ttyACM0"

    async def plug(cable: Cable, nursery: trio.Nursery) -> None:
        n = cable.plugged
        if renamed:
            await cable.plug(nursery, f"ttyUSB{n}", f"ttyACM{n}",
                             {server_port: f"ttyUSB{n}", rover_port: f"ttyACM{n}"})
        else:
            await cable.plug(nursery, server_port, rover_port)

    async def unplugger(system, cable: Cable, nursery: trio.Nursery) -> None:
        while system.server.snapshot().phase != "mapping":
            await trio.sleep(0.5)
        for _ in range(unplugs):
            await trio.sleep(20)
            await cable.unplug()
            seen["unplugged_at"] = seen.get("unplugged_at", []) + [trio.current_time()]
            await trio.sleep(UNPLUGGED_S)
            await plug(cable, nursery)

    async def main() -> None:
        cable = Cable(tmp_path)
        async with trio.open_nursery() as outer:
            await plug(cable, outer)
            with Store(":memory:") as store:
                async with open_sim_system(scenario, seed=1, store=store,
                                           roles=("hider", "seeker")) as system:
                    events = system.server.subscribe()

                    async def watch() -> None:
                        async for e in events:
                            if e.kind in ("link_open", "link_error", "hello"):
                                seen["events"].append(e)

                    outer.start_soon(watch)
                    system.server.start_serial(str(tmp_path / server_port), 115200)
                    link = parse_link(f"serial:{tmp_path / rover_port},115200")
                    lines: list[str] = []
                    async with open_remote_rover(scenario, "mapper", link, seed=1,
                                                 report=lines.append) as rover:
                        async with trio.open_nursery() as game:
                            game.start_soon(unplugger, system, cable, outer)
                            await play_game(system, report, Budget(hello=30))
                            game.cancel_scope.cancel()
                        seen["rovers"] = {r.id: r for r in system.server.snapshot().rovers}
                        seen["status"] = format_status(system.server.snapshot())
                        seen["connects"] = rover.connects
                    seen["lines"] = lines
            await cable.unplug()
            outer.cancel_scope.cancel()

    trio.run(main, clock=trio.testing.MockClock(autojump_threshold=PTY_CLOCK_THRESHOLD_S))
    return seen


def _check(seen: dict, server_port: str, unplugs: int) -> None:
    report = seen["report"]
    assert report.outcome == "found", (report.reason, report.events)
    assert len(seen.get("unplugged_at", [])) == unplugs  # the unplugs happened mid-game
    mapper = seen["rovers"]["mapper"]
    assert mapper.stats.lost == 0 and mapper.stats.up
    row = next(ln for ln in seen["status"].splitlines() if ln.split()[:1] == ["mapper"])
    assert row.split()[-3] == "0"  # the status command's "lost" column
    events = seen["events"]
    errors = [e for e in events if e.kind == "link_error"]
    # one event per unplug, at once, naming the port
    assert len(errors) == unplugs, [e.data for e in errors]
    for e, t in zip(errors, seen["unplugged_at"], strict=True):
        assert server_port in e.data["link"] and server_port in e.data["error"]
        assert e.t - t < 0.5
    opens = [e for e in events if e.kind == "link_open"]
    assert len(opens) == unplugs + 1
    for t, e in zip(seen["unplugged_at"], opens[1:], strict=True):
        assert UNPLUGGED_S <= e.t - t < UNPLUGGED_S + 1.0  # open again soon after the replug
    hellos = [e.t for e in events if e.kind == "hello" and e.rover == "mapper"]
    ends = [*seen["unplugged_at"], float("inf")]
    for e, end in zip(opens, ends, strict=True):  # hello again on each reopened port
        assert any(e.t <= t < end for t in hellos), (e.t, hellos)
    assert seen["connects"] == unplugs + 1  # and reopened its own port each time


def test_a_serial_rover_unplugged_twice_replugged_at_the_same_path_finds_with_nothing_lost(
        tmp_path) -> None:
    """Unplugged twice for 2 s mid-game, back at the same path: found, lost 0 in status."""
    seen = _game_with_unplugs(tmp_path, unplugs=2, renamed=False)
    _check(seen, "ttyUSB0", 2)


def test_a_serial_rover_back_under_a_new_kernel_name_is_found_through_its_by_id_name(
        tmp_path) -> None:
    """The adapters come back as ttyUSB1 and ttyACM1; the by-id names follow them, and the
    server and the rover, given those names, reopen them: found, nothing lost."""
    seen = _game_with_unplugs(tmp_path, unplugs=1, renamed=True)
    _check(seen, "by-id-server", 1)
