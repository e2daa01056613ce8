"""`make_nav`: the navigation actor for a rover role, as the rover tree builds it.

::

    memory = NavMemory()   # once per rover: survives navigation's restarts
    ChildSpec("nav", lambda: make_nav("hider", pool=pool, spec=hardware.spec, memory=memory),
              mailbox=64)

Each call makes a fresh actor (one per incarnation): a restarted navigation
rebuilds its state from its neighbours and the server (see `base`).
"""

from __future__ import annotations

from actors import Actor, BufferPool
from actors.firmware.addresses import Addresses
from actors.firmware.hardware import HIDER, MAPPER, ROLES, SEEKER, HardwareSpec
from actors.firmware.nav.hider import Hide
from actors.firmware.nav.mapper import MappingNav, MappingOptions
from actors.firmware.nav.options import NavMemory, NavOptions
from actors.firmware.nav.route_nav import RouteNav
from actors.firmware.nav.seeker import Seek, SeekingOptions

__all__ = ["make_nav", "NavMemory", "NavOptions"]


def make_nav(role: str, *, pool: BufferPool, spec: HardwareSpec | None = None,
             rover_id: str | None = None, options: NavOptions | None = None,
             memory: NavMemory | None = None,
             mapping: MappingOptions | None = None,
             seeking: SeekingOptions | None = None,
             addresses: Addresses | None = None) -> Actor:
    """The navigation actor of ``role``.

    Args:
        role: ``mapper``, ``hider`` or ``seeker``.
        pool: the rover's buffer pool (frames, maps and scans travel by handle).
        spec: the rover's calibration constants (body size for clearance); the bench
            calibration (`HardwareSpec.bench`) when the rover tree gives none.
        rover_id: the rover's id (accepted for the rover tree's calling convention).
        options: common tunables (`NavOptions`).
        memory: the retained record of the server's instructions, made once by the
            rover tree and passed to every incarnation (`NavMemory`); None keeps
            nothing across restarts.
        mapping: the mapper's tunables (`MappingOptions`).
        seeking: the seeker's tunables (`SeekingOptions`).
        addresses: the rover's actor names (default: those beside the actor's own).

    Raises:
        ValueError: ``role`` is not one of `ROLES`.
    """
    if spec is None:
        if role not in ROLES:
            raise ValueError(f"role must be one of {', '.join(ROLES)}, got {role!r}")
        spec = HardwareSpec.bench(role)
    if role == MAPPER:
        return MappingNav(pool=pool, spec=spec, options=options, memory=memory, mapping=mapping,
                          addresses=addresses)
    if role == HIDER:
        return RouteNav(HIDER, Hide, pool=pool, spec=spec, options=options, memory=memory,
                        addresses=addresses)
    if role == SEEKER:
        return RouteNav(SEEKER, lambda nav: Seek(nav, seeking), pool=pool, spec=spec,
                        options=options, memory=memory, addresses=addresses)
    raise ValueError(f"role must be one of {', '.join(ROLES)}, got {role!r}")
