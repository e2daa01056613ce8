"""The registered names of one rover's actors, handed to each actor.

A rover's tree registers its workers as ``<rover>/<child>`` (``mapper/motor``,
``seeker/ir`` ...). The tree makes one `Addresses` for the rover and gives it
to every actor, so no actor spells a neighbour's name itself. An actor
started on its own (a test) without one falls back to `Addresses.beside` its
own registered name.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["Addresses"]


@dataclass(frozen=True, slots=True)
class Addresses:
    """Where each actor of one rover is registered."""

    wifly: str
    """The WiFly thread (the message layer's link end)."""
    motor: str
    """Motor Control."""
    lidar: str
    """LIDAR Control (mapper)."""
    map: str
    """Map Management (mapper)."""
    ir: str
    """The IR thread (seeker)."""
    nav: str
    """Navigation."""

    @classmethod
    def of(cls, rover: str) -> Addresses:
        """The names under the rover's tree registered as ``rover`` (bare names for ``""``)."""
        prefix = f"{rover}/" if rover else ""
        return cls(*(prefix + child for child in ("wifly", "motor", "lidar", "map", "ir", "nav")))

    @classmethod
    def beside(cls, name: str, rover: str = "") -> Addresses:
        """The names beside the actor registered as ``name`` (``mapper/motor`` -> the
        mapper's); ``rover`` when ``name`` has no rover part."""
        head, sep, _ = name.rpartition("/")
        return cls.of(head if sep else rover)
