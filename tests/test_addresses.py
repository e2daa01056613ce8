"""A rover's actor names are one record, handed to every actor of its tree."""

from __future__ import annotations

import dataclasses

import pytest

from actors import BufferPool, Message
from actors.firmware.addresses import Addresses
from actors.firmware.commands import Cmd
from actors.firmware.handles import post
from supervisors.rover import rover_tree


def test_a_rovers_names_are_under_its_role() -> None:
    names = Addresses.of("seeker")
    assert (names.motor, names.nav, names.ir) == ("seeker/motor", "seeker/nav", "seeker/ir")
    assert Addresses.of("").wifly == "wifly"


def test_an_actor_alone_finds_the_names_beside_its_own() -> None:
    assert Addresses.beside("mapper/lidar") == Addresses.of("mapper")
    assert Addresses.beside("motor") == Addresses.of("")
    assert Addresses.beside("nav", "hider") == Addresses.of("hider")


def test_the_record_is_frozen() -> None:
    with pytest.raises(dataclasses.FrozenInstanceError):
        Addresses.of("hider").nav = "elsewhere"  # type: ignore[misc]


def test_the_rover_tree_hands_its_navigation_the_record() -> None:
    seen = {}

    def factory(role, *, pool, addresses, **_):
        seen["addresses"] = addresses
        return object()

    class Hardware:
        spec = None

    spec = rover_tree("hider", Hardware(), nav_factory=factory)  # type: ignore[arg-type]
    next(c for c in spec.children if c.id == "nav").start()
    assert seen["addresses"] == Addresses.of("hider")


def test_a_refused_post_gives_the_slot_back() -> None:
    pool = BufferPool(1)
    assert not post(pool, lambda m: False, Cmd.WIFLY_RX, b"x")
    got: list[Message] = []
    assert post(pool, lambda m: got.append(m) is None, Cmd.WIFLY_RX, b"y")
    assert pool.take(int(got[0].value)) == b"y"


def test_a_post_with_the_pool_dry_sends_nothing() -> None:
    pool = BufferPool(1)
    pool.put(b"held")
    got: list[Message] = []
    assert not post(pool, lambda m: got.append(m) is None, Cmd.WIFLY_RX, b"x")
    assert got == []
