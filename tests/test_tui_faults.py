"""Every fault of the catalogue can be injected from the console's fault dialog.

The live system's catalogue lists, per target, every device fault and every
actor fault (a device and its driver actor share a name: ``mapper/lidar``); the
test walks all of them through the dialog, as a person would, and checks that
the system accepted each one.
"""

from __future__ import annotations

import asyncio

from textual.app import App
from textual.widgets import Button, Input, Label, Select

from tests.test_tui_app import press, until
from tui.app import ConsoleApp
from tui.live import LiveSystem
from tui.snapshot import FaultTarget
from tui.widgets import FaultDialog
from tui.widgets.fault_dialog import FaultRequest, format_params, parse_params
from world.faults import ACTOR_FAULTS, DEVICE_FAULTS, ROLE_ACTORS
from world.scenario import load_scenario


def test_catalogue_offers_device_and_actor_faults_on_shared_names() -> None:
    async def main() -> dict[str, tuple[str, ...]]:
        system = LiveSystem(load_scenario("empty"), seed=1)
        app = ConsoleApp(system)
        async with app.run_test(size=(120, 40)):
            await until(lambda: app.snapshot is not None and app.snapshot.catalogue,
                        "the catalogue")
            return {t.target: t.kinds for t in app.snapshot.catalogue}

    kinds = asyncio.run(main())
    assert set(kinds["mapper/lidar"]) == set(DEVICE_FAULTS["lidar"]) | set(ACTOR_FAULTS)
    assert set(kinds["seeker/ir"]) == set(DEVICE_FAULTS["ir"]) | set(ACTOR_FAULTS)
    for role, actors in ROLE_ACTORS.items():
        assert set(kinds[f"{role}/motor"]) == set(DEVICE_FAULTS["motor"]) | set(ACTOR_FAULTS)
        assert set(kinds[f"{role}/wifly"]) == set(DEVICE_FAULTS["wifly"]) | set(ACTOR_FAULTS)
        for actor in actors:
            assert set(ACTOR_FAULTS) <= set(kinds[f"{role}/{actor}"])
    assert "hider/lidar" not in kinds and "mapper/ir" not in kinds


async def inject_through_dialog(app: ConsoleApp, target: str, kind: str,
                                want: dict[str, float]) -> None:
    """Open the dialog, choose ``kind`` on ``target`` for 2 s, check the parameter field
    shows ``want``, inject, and wait for the system's answer and the dialog to close."""
    press(app, "f")
    await until(lambda: isinstance(app.screen, FaultDialog) and app.screen.query(Select)
                and all(w.is_mounted for w in app.screen.query(Select)), "fault dialog")
    dialog = app.screen
    dialog.query_one("#target", Select).value = target
    await until(lambda: kind in [v for _, v in dialog.query_one("#kind", Select)._options],
                f"kinds of {target}")
    dialog.query_one("#kind", Select).value = kind
    await until(lambda: dialog.query_one("#params", Input).value == format_params(want),
                f"parameters of {kind}")
    dialog.query_one("#duration", Input).value = "2"
    n = len(app.results)
    dialog.query_one("#inject", Button).press()
    await until(lambda: len(app.results) > n, f"{kind} on {target}")
    result = app.results[-1]
    assert (result.command, result.status) == ("inject_fault", "ok"), (target, kind,
                                                                       result.reason)
    await until(lambda: not isinstance(app.screen, FaultDialog), "dialog closed")


def test_every_catalogue_fault_is_injected_from_the_dialog() -> None:
    system = LiveSystem(load_scenario("empty"), seed=1)
    app = ConsoleApp(system)
    walked: list[tuple[str, str, dict]] = []

    async def main() -> None:
        async with app.run_test(size=(120, 40), notifications=True):
            await until(lambda: app.snapshot is not None and app.snapshot.catalogue,
                        "the catalogue")
            press(app, "space")  # paused: faults are still injected, the game holds still
            for target in app.snapshot.catalogue:
                for kind in target.kinds:
                    want = target.params.get(kind, {})
                    await inject_through_dialog(app, target.target, kind, want)
                    walked.append((target.target, kind, want))

    asyncio.run(main())
    injected = [args for method, args in system.calls if method == "inject_fault"]
    assert [(t, k, p) for t, k, _, p in injected] == walked
    assert len(walked) == sum(len(t.kinds) for t in app.snapshot.catalogue)
    assert ("mapper/lidar", "dead", {}) in walked
    assert ("mapper/lidar", "noisy", {"sigma_cm": 10.0}) in walked
    assert ("seeker/ir", "stuck_high", {}) in walked
    assert ("hider/wifly", "down", {}) in walked and ("hider/motor", "stalled", {}) in walked


def test_fault_parameters_parse_and_refuse_what_the_kind_does_not_take() -> None:
    assert parse_params("sigma_cm=12", {"sigma_cm": 10.0}) == {"sigma_cm": 12.0}
    assert parse_params("", {"sigma_cm": 10.0}) == {}
    for bad, why in (("sigma=1", "no parameter"), ("sigma_cm", "NAME=NUMBER"),
                     ("sigma_cm=x", "must be a number"), ("sigma_cm=-1", ">= 0")):
        try:
            parse_params(bad, {"sigma_cm": 10.0})
        except ValueError as exc:
            assert why in str(exc)
        else:
            raise AssertionError(f"{bad!r} was accepted")


#: a console's catalogue with the mapper attached: its targets come after every
#: simulated rover's
ATTACHED_LAST = tuple(FaultTarget(f"{role}/{dev}", ("crash", "hang"))
                      for role in ("hider", "seeker") for dev in ("wifly", "motor", "ir", "nav")
                      ) + (FaultTarget("mapper/lidar", ("dead", "crash")),
                           FaultTarget("mapper/nav", ("crash",)),
                           FaultTarget("mapper/link", ("down", "loss"),
                                       {"loss": {"percent": 20.0}}))


class _DialogHost(App):
    """An app that opens the fault dialog on ``catalogue`` and keeps what it returns."""

    def __init__(self, catalogue: tuple[FaultTarget, ...]) -> None:
        super().__init__()
        self.catalogue = catalogue
        self.result: FaultRequest | None | str = "open"

    def on_mount(self) -> None:
        self.push_screen(FaultDialog(self.catalogue), self._done)

    def _done(self, result: FaultRequest | None) -> None:
        self.result = result


def test_an_attached_rovers_targets_are_a_few_keys_away_in_the_fault_dialog() -> None:
    """The dialog groups targets by rover: typing the rover's initial in the rover list
    leaves only its targets, so the attached mapper's link (last of 11 targets) is chosen,
    given a kind and injected with 14 key presses."""
    keys = ["enter", "m", "enter",            # rover: mapper
            "tab", "enter", "up", "enter",    # target: its last, mapper/link
            "tab", "enter", "down", "down", "enter",  # kind: loss (percent=20 shown)
            "tab", "enter"]                   # duration empty: submitted, until cleared
    seen: dict[str, object] = {}

    async def main() -> FaultRequest | None | str:
        app = _DialogHost(ATTACHED_LAST)
        async with app.run_test(size=(100, 40)) as pilot:
            await pilot.pause()
            dialog = app.screen
            assert isinstance(dialog, FaultDialog)
            seen["all"] = dialog.targets()
            for key in keys[:3]:
                await pilot.press(key)
            await pilot.pause()
            seen["mapper"] = [v for _, v in dialog.query_one("#target", Select)._options
                              if isinstance(v, str)]
            for key in keys[3:]:
                await pilot.press(key)
            await pilot.pause()
        return app.result

    result = asyncio.run(main())
    assert seen["all"] == [t.target for t in ATTACHED_LAST]
    assert seen["mapper"] == ["mapper/lidar", "mapper/nav", "mapper/link"]
    assert result == FaultRequest("inject", "mapper/link", "loss", None, {"percent": 20.0})


def test_fault_dialog_groups_targets_by_rover_and_keeps_a_chosen_target_of_that_rover() -> None:
    """Targets of interleaved catalogue entries are listed rover by rover; choosing a
    target's own rover keeps it, another rover's clears it, no rover lists all again."""
    catalogue = (FaultTarget("mapper/lidar", ("dead",)), FaultTarget("hider/motor", ("crash",)),
                 FaultTarget("mapper.lidar", ("stuck",)), FaultTarget("hider/nav", ("hang",)))

    async def main() -> list:
        app = _DialogHost(catalogue)
        out: list = []
        async with app.run_test(size=(100, 40)) as pilot:
            await pilot.pause()
            dialog = app.screen
            rover, target = dialog.query_one("#rover", Select), dialog.query_one("#target", Select)
            out.append(dialog.targets())
            target.value = "hider/nav"
            for choice in ("hider", "mapper", None):
                if choice is None:
                    rover.clear()
                else:
                    rover.value = choice
                await pilot.pause()
                out.append((None if target.is_blank() else target.value,
                            [v for _, v in target._options if isinstance(v, str)]))
        return out

    grouped, hider, mapper, every = asyncio.run(main())
    assert grouped == ["mapper/lidar", "mapper.lidar", "hider/motor", "hider/nav"]
    assert hider == ("hider/nav", ["hider/motor", "hider/nav"])
    assert mapper == (None, ["mapper/lidar", "mapper.lidar"])
    assert every == (None, grouped)


def test_fault_dialog_asks_for_a_target_and_a_kind_before_injecting() -> None:
    """Inject with nothing chosen says what is missing and keeps the dialog open."""
    async def main() -> tuple[object, str]:
        app = _DialogHost(ATTACHED_LAST)
        async with app.run_test(size=(100, 40)) as pilot:
            await pilot.pause()
            app.screen.query_one("#inject", Button).press()
            await pilot.pause()
            return app.result, str(app.screen.query_one("#error", Label).render())

    assert asyncio.run(main()) == ("open", "choose a target and a kind")
