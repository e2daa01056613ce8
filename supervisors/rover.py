"""One supervision tree per rover: the seed's threads as supervised actors.

``rover_tree(role, hardware)`` returns a `SupervisorSpec`; start it under the
rover's role (``system.start_supervisor(spec, "mapper")``) so its workers
register as ``mapper/motor``, ``mapper/wifly`` ...; each actor is handed the
rover's `Addresses` record of those names, so none spells a neighbour's name.

Children, in start order, with queue depths and watchdog deadlines::

    id      actor             roles    mailbox  watchdog  why this depth
    wifly   Wifly             all       256     1.0 s     Int B chunks per tick + sends
    motor   MotorControl      all       512     0.5 s     Int E: ~3 per tread per 50 ms tick
    lidar   LidarControl      mapper   4096     1.0 s     Int A: ~200 samples per tick at
                                                          full PWM; a 1 s stall fits
    map     MapManagement     mapper     64     2.0 s     one scan batch per tick
    ir      IrSensor          seeker    256     0.5 s     50 Hz samples
    nav     (nav_factory)     all       128     2.0 s     poses, motion, map updates, frames

ISRs (`actors.firmware.drivers.isr`) are not actors: they run in the hardware's
interrupt context and post with ``send_nowait`` into these mailboxes, which
belong to the supervisor and survive restarts. The ISR objects are made here,
once, so their counters (posted, dropped) survive restarts; each owning actor
attaches its ISR when it starts. One `BufferPool` per rover carries bulk data
(bytes, scans, map snapshots, frames).

Strategy: ``one_for_one``, intensity 10 restarts in 10 s, restart backoff
0.05..1 s. Why:

* an ISR-side or driver crash (wifly, motor, lidar, map, ir) must not restart
  navigation: the game state lives there;
* a navigation crash must not restart the drivers: the LIDAR keeps spinning,
  the map keeps growing, the link stays up; the new navigation asks for the
  pose (``MOTOR_GET_POSE``) and the map (``MAP_GET``) and resumes from the
  last known pose, not from scratch;
* no actor depends on a sibling's incarnation: each one rebuilds its state
  from its own retained memory (motor: pose; wifly: the reliable session) or
  from what it asks its neighbours (lidar: the pose; map: navigation's last
  snapshot). So restarting siblings with it (``rest_for_one`` /
  ``one_for_all``) would only lose more state.

Everything is flat under the rover's supervisor because a nested supervisor
would change the registered names (``mapper/drivers/motor``), and the names
are the firmware's contract.
"""

from __future__ import annotations

import importlib
import inspect
from collections.abc import Callable
from typing import Any

from actors import Actor, BufferPool, Message, ValueType
from actors.firmware.addresses import Addresses
from actors.firmware.commands import Cmd
from actors.firmware.drivers.ir import IrSensor
from actors.firmware.drivers.isr import IrAdcIsr, LidarUartIsr, MotorCounterIsr, WiflyUartIsr
from actors.firmware.drivers.lidar import LidarControl
from actors.firmware.drivers.motor import MotorControl, MotorTuning, PoseMemory
from actors.firmware.drivers.wifly import LinkMemory, Wifly
from actors.firmware.hardware import ROLES, RoverHardware
from actors.firmware.mapping.map_management import MapManagement
from supervisors.supervisor import Backoff, ChildSpec, SupervisorSpec

__all__ = ["MAILBOX", "WATCHDOG_S", "IdleNav", "rover_tree"]

MAILBOX = {"wifly": 256, "motor": 512, "lidar": 4096, "map": 64, "ir": 256, "nav": 128}
"""Queue depth per child id [messages]."""

WATCHDOG_S = {"wifly": 1.0, "motor": 0.5, "lidar": 1.0, "map": 2.0, "ir": 0.5, "nav": 2.0}
"""Handling deadline per message (per burst for burst handlers) [s]."""

POOL_SLOTS = 256
"""Buffer pool slots per rover."""


class _MailboxPost:
    """An ISR's non-blocking post into one mailbox (False when dropped or not yet bound)."""

    __slots__ = ("system", "name")

    def __init__(self, name: str) -> None:
        self.system: Any = None
        self.name = name

    def __call__(self, message: Message) -> bool:
        if self.system is None:
            return False
        cell = self.system.whereis(self.name)
        return cell is not None and cell.mailbox.send_nowait(message)


class IdleNav(Actor):
    """A stand-in navigation that only releases the handles it receives.

    Used when no navigation is available (tests of the drivers, and until the
    real navigation is importable).
    """

    def __init__(self, pool: BufferPool) -> None:
        self.pool = pool

    async def handle(self, message: Any) -> None:
        if isinstance(message, Message) and message.type == ValueType.HANDLE \
                and message.command in (Cmd.NAV_MAP_UPDATE, Cmd.NAV_NET, Cmd.NAV_MAP_DOWNLOAD):
            self.pool.take(int(message.value))


def _default_nav_factory() -> Callable[..., Actor]:
    """The real navigation (``actors.firmware.nav.factory.make_nav``) when it exists."""
    try:
        return importlib.import_module("actors.firmware.nav.factory").make_nav
    except (ImportError, AttributeError):
        return lambda role, *, pool, **_: IdleNav(pool)


def _accepts(factory: Callable[..., Any], keyword: str) -> bool:
    try:
        params = inspect.signature(factory).parameters
    except (TypeError, ValueError):
        return False
    return keyword in params


def _nav_options(factory: Callable[..., Actor], nav_options: dict[str, Any] | None,
                 names: Addresses) -> dict[str, Any]:
    """The keyword arguments navigation is made with: ``nav_options``, plus the rover's
    names and a retained `NavMemory` where the factory takes them and none was given."""
    options = dict(nav_options or {})
    if "addresses" not in options and _accepts(factory, "addresses"):
        options["addresses"] = names
    if "memory" not in options and _accepts(factory, "memory"):
        try:  # navigation's retained memory, made once per tree like PoseMemory
            options["memory"] = importlib.import_module("actors.firmware.nav.options").NavMemory()
        except (ImportError, AttributeError):
            pass
    return options


class _Isrs:
    """The rover's ISR objects: made once per tree (their counters survive restarts),
    each posting into its owner's mailbox.

    The posts learn the running system from `attach`, the ``init`` hook of every
    driver's child spec, which runs on each incarnation before the actor's ``on_start``.
    """

    def __init__(self, role: str, names: Addresses, pool: BufferPool) -> None:
        self.posts = {c: _MailboxPost(getattr(names, c)) for c in ("motor", "wifly", "lidar", "ir")}
        self.motor = MotorCounterIsr(self.posts["motor"])
        self.wifly = WiflyUartIsr(self.posts["wifly"], pool)
        self.lidar = LidarUartIsr(self.posts["lidar"]) if role == "mapper" else None
        self.ir = IrAdcIsr(self.posts["ir"]) if role == "seeker" else None

    def attach(self, actor: Actor) -> None:
        """Point the ISR posts at the system ``actor`` runs in (a child spec's ``init``)."""
        for post in self.posts.values():
            post.system = actor.ctx.system


class _Retained:
    """One retained-memory object per tree, made at the first incarnation that needs it."""

    def __init__(self, make: Callable[[], Any]) -> None:
        self._make = make
        self._obj: Any = None

    def get(self) -> Any:
        if self._obj is None:
            self._obj = self._make()
        return self._obj


def rover_tree(role: str, hardware: RoverHardware, *, rover_id: str | None = None,
               nav_factory: Callable[..., Actor] | None = None,
               nav_options: dict[str, Any] | None = None, token: str | None = None,
               motor_tuning: MotorTuning | None = None, map_size_cm: tuple[float, float] = (
                   2400.0, 2400.0), ir_rate_hz: float = 50.0,
               intensity: int = 10, period: float = 10.0,
               hold_until_welcome: bool = False, telemetry: Any = None,
               streams: tuple[str, ...] = (), faults: Any = None) -> SupervisorSpec:
    """The supervision tree of one rover (see the module docstring).

    Args:
        role: ``mapper``, ``hider`` or ``seeker``.
        hardware: the rover's devices (simulated or a bridge to a real rover).
        rover_id: the id said in hello (default: the role).
        nav_factory: makes the navigation actor, called for every incarnation as
            ``nav_factory(role, pool=pool, spec=hardware.spec, rover_id=rover_id,
            **nav_options)``; default ``actors.firmware.nav.factory.make_nav`` (or an idle
            stand-in when it is not importable). A factory with a ``memory``
            parameter gets one ``NavMemory`` per tree (kept across restarts)
            unless ``nav_options`` brings one.
        nav_options: extra keyword arguments for ``nav_factory``.
        token: the shared secret for hello, when the server asks for one.
        motor_tuning: Motor Control constants.
        map_size_cm: Map Management's grid extent [cm] (mapper).
        ir_rate_hz: IR timer rate [Hz] (seeker).
        intensity: restarts allowed within ``period`` before the tree gives up.
        period: [s].
        hold_until_welcome: the WiFly sends nothing but hello until the welcome (a rover
            on a real link; see `Wifly`).
        telemetry: the WiFly's `TelemetryLane` (a rover that streams telemetry).
        streams: the telemetry streams offered in hello.
        faults: the WiFly's `FaultPort` (a rover that takes faults over the link).

    Raises:
        ValueError: unknown role.
    """
    if role not in ROLES:
        raise ValueError(f"role must be one of {', '.join(ROLES)}, got {role!r}")
    rover_id = rover_id or role
    names = Addresses.of(role)  # the tree is started under the rover's role
    pool = BufferPool(POOL_SLOTS, name=f"{role}-pool")
    factory = nav_factory or _default_nav_factory()
    options = _nav_options(factory, nav_options, names)

    # retained memory (survives actor restarts; a new tree is a rover reset)
    pose_memory = PoseMemory()
    link_memory = _Retained(lambda: LinkMemory(owner=rover_id))  # lazily: it reads the clock
    isrs = _Isrs(role, names, pool)

    def make_wifly() -> Actor:
        return Wifly(hardware, pool, rover_id=rover_id, role=role, token=token,
                     memory=link_memory.get(), isr=isrs.wifly, addresses=names,
                     hold_until_welcome=hold_until_welcome, telemetry=telemetry,
                     streams=streams, faults=faults)

    def child(cid: str, start: Callable[[], Actor], *, driver: bool = True) -> ChildSpec:
        return ChildSpec(cid, start, mailbox=MAILBOX[cid], watchdog=WATCHDOG_S[cid],
                         init=isrs.attach if driver else None)

    children = [
        child("wifly", make_wifly),
        child("motor", lambda: MotorControl(hardware, pose_memory, isr=isrs.motor,
                                            lidar=role == "mapper",
                                            tuning=motor_tuning, addresses=names)),
    ]
    children += [child(cid, start) for cid, start in
                 _sensor_starts(role, hardware, pool, names, isrs, map_size_cm, ir_rate_hz)]
    children.append(child("nav", lambda: factory(role, pool=pool, spec=hardware.spec,
                                                 rover_id=rover_id, **options), driver=False))
    return SupervisorSpec(children, intensity=intensity, period=period,
                          backoff=Backoff(min=0.05, max=1.0, jitter=0.1, reset_after=10.0))


def _sensor_starts(role: str, hardware: RoverHardware, pool: BufferPool, names: Addresses,
                   isrs: _Isrs, map_size_cm: tuple[float, float], ir_rate_hz: float,
                   ) -> list[tuple[str, Callable[[], Actor]]]:
    """The children a role has beyond the WiFly, the motor and navigation, in start order,
    with their start functions: the mapper's LIDAR and Map Management (told from its
    second incarnation on that it restarts), the seeker's IR sensor."""
    if role == "mapper":
        map_starts = [0]

        def make_map() -> Actor:
            map_starts[0] += 1
            return MapManagement(pool, hardware.spec, size_cm=map_size_cm,
                                 restarted=map_starts[0] > 1, addresses=names)

        return [("lidar", lambda: LidarControl(hardware, pool, isr=isrs.lidar, addresses=names)),
                ("map", make_map)]
    if role == "seeker":
        return [("ir", lambda: IrSensor(hardware, rate_hz=ir_rate_hz, adc_isr=isrs.ir,
                                        addresses=names))]
    return []
