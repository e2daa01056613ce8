"""The fault dialog: inject a catalogue fault on a target with a duration, or clear one.

It offers exactly what the snapshot's catalogue lists, so a person cannot pick
a kind the target does not accept: per target every device fault and every
actor fault (``mapper/lidar`` is both a device and an actor: ``dead`` ...
``noisy`` and ``crash`` / ``hang`` / ``flood``). A kind that takes parameters
fills the parameter field with its defaults (``sigma_cm=10``), to edit.
Dismisses with a `FaultRequest` or None.

Targets are grouped by rover: the target list holds every rover's targets, one
rover after another, until a rover is chosen in the first list, and then that
rover's only, so an attached rover's targets (listed after the simulated
ones) are two choices away by keyboard, as any rover's are.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, Vertical
from textual.screen import ModalScreen
from textual.widgets import Button, Input, Label, Select

from tui.snapshot import ActiveFault, FaultTarget

__all__ = ["FaultDialog", "FaultRequest", "parse_duration", "parse_params", "format_params",
           "rover_of"]


def rover_of(target: str) -> str:
    """The rover a catalogue target belongs to: ``mapper/lidar`` and ``mapper.lidar`` ->
    ``mapper``."""
    return target.replace(".", "/").partition("/")[0]


@dataclass(frozen=True, slots=True)
class FaultRequest:
    """What the person asked for."""

    action: str
    """``inject`` or ``clear``."""
    target: str = ""
    """Catalogue target (inject), or fault id / target (clear)."""
    kind: str = ""
    """Fault kind (inject)."""
    duration_s: float | None = None
    """Simulated duration [s] (inject); None until cleared."""
    params: dict[str, float] = field(default_factory=dict)
    """The kind's parameters (inject), as edited."""


def format_params(params: dict[str, float]) -> str:
    """``{"sigma_cm": 10.0}`` -> ``sigma_cm=10``."""
    return " ".join(f"{k}={v:g}" for k, v in params.items())


def parse_params(text: str, allowed: dict[str, float]) -> dict[str, float]:
    """``"sigma_cm=12 ..."`` (spaces or commas between) -> ``{"sigma_cm": 12.0}``.

    Raises:
        ValueError: a word that is not NAME=NUMBER, a name the kind does not take,
            or a negative value.
    """
    out: dict[str, float] = {}
    for word in text.replace(",", " ").split():
        name, sep, value = word.partition("=")
        if not sep:
            raise ValueError(f"parameters are NAME=NUMBER, got {word!r}")
        if name not in allowed:
            raise ValueError(f"no parameter {name!r}; this kind takes "
                             f"{', '.join(allowed) or 'none'}")
        try:
            number = float(value)
        except ValueError:
            raise ValueError(f"{name} must be a number, got {value!r}") from None
        if not number >= 0:
            raise ValueError(f"{name} must be >= 0, got {value!r}")
        out[name] = number
    return out


def parse_duration(text: str) -> float | None:
    """``""`` -> None (until cleared); ``"5"`` -> 5.0 [s].

    Raises:
        ValueError: when the text is not a positive number of seconds.
    """
    text = text.strip().removesuffix("s").strip()
    if not text:
        return None
    try:
        value = float(text)
    except ValueError:
        raise ValueError(f"duration must be a number of seconds, got {text!r}") from None
    if not value > 0:
        raise ValueError(f"duration must be > 0 s, got {text!r}")
    return value


class FaultDialog(ModalScreen[FaultRequest | None]):
    """Choose target, kind and duration; or choose an active fault to clear."""

    BINDINGS = [Binding("escape", "cancel", "Cancel")]

    DEFAULT_CSS = """
    FaultDialog { align: center middle; }
    FaultDialog > Vertical {
        width: 60; max-width: 100%; height: auto; max-height: 100%;
        border: thick $error; background: $surface; padding: 0 1;
        overflow-y: auto;
    }
    FaultDialog Select, FaultDialog Input { width: 1fr; }
    FaultDialog Horizontal { height: auto; }
    FaultDialog Label { margin-top: 1; }
    FaultDialog #error { color: $error; margin: 0; }
    """

    def __init__(self, catalogue: tuple[FaultTarget, ...],
                 active: tuple[ActiveFault, ...] = ()) -> None:
        super().__init__()
        self.catalogue = catalogue
        self.active = active
        self._kinds: dict[str, tuple[str, ...]] = {}
        self._params: dict[tuple[str, str], dict[str, float]] = {}
        self._rovers: dict[str, list[str]] = {}
        """Rover -> its targets, rovers and targets in catalogue order."""
        for t in catalogue:  # a target listed twice offers the kinds of both
            kinds = self._kinds.get(t.target, ())
            if not kinds:
                self._rovers.setdefault(rover_of(t.target), []).append(t.target)
            self._kinds[t.target] = kinds + tuple(k for k in t.kinds if k not in kinds)
            for kind, params in t.params.items():
                self._params[(t.target, kind)] = dict(params)

    def targets(self, rover: str | None = None) -> list[str]:
        """The target list: ``rover``'s targets, or every rover's grouped by rover."""
        rovers = [rover] if rover in self._rovers else list(self._rovers)
        return [t for r in rovers for t in self._rovers[r]]

    def compose(self) -> ComposeResult:
        with Vertical():
            yield Label("[b]Inject a fault[/b]")
            yield Select([(r, r) for r in self._rovers], prompt="rover: all", id="rover")
            yield Select([(t, t) for t in self.targets()], prompt="target", id="target")
            yield Select([], prompt="kind", id="kind")
            yield Input(placeholder="duration [s], empty = until cleared", id="duration")
            yield Input(placeholder="parameters: none", id="params", disabled=True)
            yield Label("", id="error")
            with Horizontal():
                yield Button("Inject", variant="error", id="inject")
                yield Button("Cancel", id="cancel")
            if self.active:
                yield Label("[b]Clear an active fault[/b]")
                yield Select([("all faults", "*")] + [
                    (f"{f.id}: {f.kind} on {f.target}", f.id) for f in self.active],
                    prompt="fault", id="active")
                yield Button("Clear", variant="success", id="clear")

    def on_select_changed(self, event: Select.Changed) -> None:
        if event.select.id == "rover":
            rover = None if event.select.is_blank() else str(event.value)
            target = self.query_one("#target", Select)
            chosen = target.value
            target.set_options([(t, t) for t in self.targets(rover)])
            if chosen in self.targets(rover):  # the rover of the chosen target: keep it
                target.value = chosen
        elif event.select.id == "target":
            kinds = self._kinds.get(str(event.value), ())
            self.query_one("#kind", Select).set_options([(k, k) for k in kinds])
            self._show_params({})
        elif event.select.id == "kind":
            target = self.query_one("#target", Select).value
            self._show_params(self._params.get((str(target), str(event.value)), {}))

    def _show_params(self, params: dict[str, float]) -> None:
        box = self.query_one("#params", Input)
        box.value = format_params(params)
        box.disabled = not params
        box.placeholder = ("parameters NAME=NUMBER" if params else "parameters: none")

    def on_button_pressed(self, event: Button.Pressed) -> None:
        event.stop()
        if event.button.id == "cancel":
            self.dismiss(None)
        elif event.button.id == "inject":
            self._inject()
        elif event.button.id == "clear":
            active = self.query_one("#active", Select)
            if active.is_blank():
                self._error("choose a fault to clear")
            else:
                self.dismiss(FaultRequest("clear", str(active.value)))

    def on_input_submitted(self, event: Input.Submitted) -> None:
        event.stop()
        self._inject()

    def _inject(self) -> None:
        target_list, kind_list = self.query_one("#target", Select), self.query_one("#kind", Select)
        if target_list.is_blank() or kind_list.is_blank():
            self._error("choose a target and a kind")
            return
        target, kind = target_list.value, kind_list.value
        try:
            duration = parse_duration(self.query_one("#duration", Input).value)
            params = parse_params(self.query_one("#params", Input).value,
                                  self._params.get((str(target), str(kind)), {}))
        except ValueError as exc:
            self._error(str(exc))
            return
        self.dismiss(FaultRequest("inject", str(target), str(kind), duration, params))

    def _error(self, text: str) -> None:
        self.query_one("#error", Label).update(text)

    def action_cancel(self) -> None:
        self.dismiss(None)
