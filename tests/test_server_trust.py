"""Who a rover is: ids the server was given, tokens, takeover, guessing, simulated roles."""

from __future__ import annotations

import hmac

import pytest
import trio
import trio.testing

from server.protocol import decode_line
from server.server import ServerConfig, open_server
from server.store import Store
from tests.raw_client import Outside, errors_of, hello, open_raw_tcp, read_until_closed


def run(fn) -> None:
    trio.run(fn, clock=trio.testing.MockClock(autojump_threshold=0))


def _welcomed(frames) -> bool:
    return any(f.cmd == "welcome" for f in frames)


def test_unknown_id_is_refused_and_never_becomes_the_mapper() -> None:
    """A tokenless hello for an id the server was not given gets auth and no role."""
    async def main() -> None:
        async with open_server(Store(":memory:"), ServerConfig(rovers=frozenset({"m1"}))) as s:
            x = Outside(s)
            x.send(hello("x9", "mapper"))
            await trio.sleep(0.2)
            got = x.frames()
            assert errors_of(got) == [("auth", "unknown rover id 'x9': the server was not "
                                               "given it")]
            assert not _welcomed(got) and s.snapshot().rovers == ()
            r = await s.command("start_mapping")
            assert (r.ok, r.reason) == (False, "no mapper has said hello yet")

    run(main)


def test_open_enrolment_welcomes_an_id_it_was_not_given() -> None:
    """With open enrolment any well-formed id is welcomed."""
    async def main() -> None:
        config = ServerConfig(open_enrolment=True)
        async with open_server(Store(":memory:"), config) as s:
            x = Outside(s)
            x.send(hello("x9", "mapper"))
            await trio.sleep(0.2)
            assert _welcomed(x.frames())

    run(main)


def test_hello_may_not_claim_a_simulated_rovers_role_or_id() -> None:
    """An outside hello as the simulated seeker's role, or with its id, is refused."""
    async def main() -> None:
        config = ServerConfig(rovers=frozenset({"s9", "seeker"}), open_enrolment=True)
        async with open_server(Store(":memory:"), config) as s:
            sim_inbox: list[bytes] = []
            sim = s.attach_memory(sim_inbox.append)  # trusted: the simulated seeker
            sim.feed(hello("seeker", "seeker"))
            await trio.sleep(0.2)
            x = Outside(s)
            x.send(hello("s9", "seeker"))
            await trio.sleep(0.2)
            assert errors_of(x.frames()) == [("auth", "role 'seeker' is played by a "
                                                      "simulated rover")]
            x.send(hello("seeker", "hider"))
            await trio.sleep(0.2)
            assert errors_of(x.frames()) == [("auth", "id 'seeker' is a simulated rover's")]
            (view,) = s.snapshot().rovers
            assert (view.id, view.link) == ("seeker", "memory")

    run(main)


def test_configured_simulated_role_is_reserved_before_its_rover_says_hello() -> None:
    """``simulated`` reserves a role even before the simulated rover is attached."""
    async def main() -> None:
        config = ServerConfig(rovers=frozenset({"h1"}), simulated=("hider",))
        async with open_server(Store(":memory:"), config) as s:
            x = Outside(s)
            x.send(hello("h1", "hider"))
            await trio.sleep(0.2)
            assert errors_of(x.frames()) == [("auth", "role 'hider' is played by a "
                                                      "simulated rover")]

    run(main)


def test_tokenless_takeover_of_a_live_session_waits_for_silence() -> None:
    """Without tokens a second link cannot take a live rover's id; after the old
    link was silent for down_after_s it can, and the old link is closed."""
    async def main() -> None:
        async with open_server(Store(":memory:"), ServerConfig(rovers=frozenset({"h1"}))) as s:
            real, thief = Outside(s, name="real"), Outside(s, name="thief")
            real.send(hello("h1", "hider"))
            await trio.sleep(0.5)
            assert _welcomed(real.frames())
            for _ in range(3):  # the real rover keeps talking; the thief keeps trying
                real.send(b'{"cmd":"heartbeat","type":"beat","data":null}\n')
                thief.send(hello("h1", "hider"))
                await trio.sleep(1.0)
            got = thief.frames()
            assert not _welcomed(got)
            assert errors_of(got)[0] == ("auth", "'h1' is live on another link; without a "
                                                 "token a new link may take over after 5 s "
                                                 "of silence")
            assert [v.link for v in s.snapshot().rovers] == ["real"]
            # the same link may say hello again at any time (a rover that rebooted)
            real.send(hello("h1", "hider"))
            await trio.sleep(0.2)
            assert _welcomed(real.frames())
            # the real link goes silent past down_after_s: a new link may take over
            await trio.sleep(6.0)
            newer = Outside(s, name="newer")
            newer.send(hello("h1", "hider"))
            await trio.sleep(0.2)
            assert _welcomed(newer.frames())
            assert [v.link for v in s.snapshot().rovers] == ["newer"]
            assert real.closed_by_server

    run(main)


def test_takeover_with_the_token_is_at_once_and_without_it_refused() -> None:
    """With a per-rover token, a live session moves only to a link that gives it."""
    async def main() -> None:
        config = ServerConfig(rovers=frozenset({"h1"}), tokens={"h1": "sesame"})
        async with open_server(Store(":memory:"), config) as s:
            a, b, c = Outside(s, name="a"), Outside(s, name="b"), Outside(s, name="c")
            a.send(hello("h1", "hider", token="sesame"))
            await trio.sleep(0.2)
            assert _welcomed(a.frames())
            b.send(hello("h1", "hider"))
            b.send(hello("h1", "hider", token="wrong"))
            await trio.sleep(0.2)
            assert [f for f, _ in errors_of(b.frames())] == ["auth", "auth"]
            c.send(hello("h1", "hider", token="sesame"))
            await trio.sleep(0.2)
            assert _welcomed(c.frames())
            assert [v.link for v in s.snapshot().rovers] == ["c"]
            assert a.closed_by_server  # no flapping: the replaced link is closed

    run(main)


def test_one_rover_id_per_link() -> None:
    """A link bound to one id cannot say hello as another."""
    async def main() -> None:
        config = ServerConfig(rovers=frozenset({"h1", "s1"}))
        async with open_server(Store(":memory:"), config) as s:
            x = Outside(s)
            x.send(hello("h1", "hider"))
            x.send(hello("s1", "seeker"))
            await trio.sleep(0.2)
            got = x.frames()
            assert _welcomed(got)
            assert errors_of(got) == [("not_allowed", "this link speaks for 'h1'; one rover "
                                                      "id per link")]

    run(main)


def test_beyond_loopback_every_id_needs_a_token() -> None:
    """A hello from a non-loopback peer for an id without a token is refused; and
    listening beyond loopback is refused while some accepted id has no token."""
    async def main() -> None:
        config = ServerConfig(rovers=frozenset({"h1", "s1"}), tokens={"h1": "sesame"})
        async with open_server(Store(":memory:"), config) as s:
            far = Outside(s, peer="192.0.2.7")
            far.send(hello("s1", "seeker"))
            await trio.sleep(0.2)
            assert errors_of(far.frames()) == [("auth", "'s1' has no token and this link is "
                                                        "not loopback")]
            near = Outside(s, peer="127.0.0.1")
            near.send(hello("s1", "seeker"))
            await trio.sleep(0.2)
            assert _welcomed(near.frames())
            with pytest.raises(ValueError, match="refusing to listen on 0.0.0.0: not loopback "
                                                 "and 's1' has no token"):
                await s.listen_tcp("0.0.0.0", 0)

    run(main)


def test_tokens_are_compared_in_constant_time(monkeypatch) -> None:
    """The token check goes through hmac.compare_digest."""
    calls = []
    real = hmac.compare_digest

    def spy(a, b):
        calls.append((a, b))
        return real(a, b)

    monkeypatch.setattr("server.trust.hmac.compare_digest", spy)

    async def main() -> None:
        config = ServerConfig(rovers=frozenset({"h1"}), tokens={"*": "sesame"})
        async with open_server(Store(":memory:"), config) as s:
            x = Outside(s)
            x.send(hello("h1", "hider", token="sesame"))
            await trio.sleep(0.2)
            assert _welcomed(x.frames())

    run(main)
    assert calls == [(b"sesame", b"sesame")]


def test_guessing_closes_the_link_and_blocks_the_address() -> None:
    """Five wrong tokens close the TCP connection (the right one is never tried on it);
    the address is then blocked for a while: a new connection from it is heard for one
    hello, closed when that is refused. The failures are stored as one event and one
    summary, not one row per guess."""
    store = Store(":memory:")

    async def main() -> None:
        config = ServerConfig(rovers=frozenset({"h1"}), tokens={"h1": "sesame"})
        async with open_server(store, config) as s:
            port = await s.listen_tcp("127.0.0.1", 0)
            stream = await open_raw_tcp(port)
            for k in range(5):
                await stream.send_all(hello("h1", "hider", token=f"guess{k}"))
            await stream.send_all(hello("h1", "hider", token="sesame"))
            got, closed = await read_until_closed(stream, 5)
            assert closed
            frames = [decode_line(x) for x in got.splitlines()]
            assert [f.cmd for f in frames] == ["error"] * 5
            assert not s.snapshot().rovers
            again = await open_raw_tcp(port)  # blocked address: one hello, then closed
            await again.send_all(hello("h1", "hider", token="guess5")
                                 + hello("h1", "hider", token="sesame"))
            got, closed = await read_until_closed(again, 1)
            assert closed and b'"welcome"' not in got
            await trio.sleep(1.5)  # the first block is 1 s
            ok = await open_raw_tcp(port)
            await ok.send_all(hello("h1", "hider", token="sesame"))
            got, _ = await read_until_closed(ok, 0.5)
            assert b'"welcome"' in got
            assert s.snapshot().refused["auth_failed"] == 6

    run(main)
    kinds = [k for _, k, _, _ in store.events()]
    assert kinds.count("auth_failed") == 1
    summary = [d for _, k, _, d in store.events() if k == "auth_failed_summary"]
    assert [d["count"] for d in summary] == [5]  # the first was stored as it happened


def test_bad_hellos_from_a_shared_address_cannot_lock_a_token_holder_out() -> None:
    """Five bad hellos from 127.0.0.1 block it; a rover with the right token from the same
    address is welcomed at once all the same, and the block goes on for everyone else:
    a tokenless hello (which loopback would otherwise admit) and a wrong token are
    refused, their connections closed."""
    async def main() -> None:
        config = ServerConfig(rovers=frozenset({"h1", "h2"}), tokens={"h1": "sesame"})
        async with open_server(Store(":memory:"), config) as s:
            port = await s.listen_tcp("127.0.0.1", 0)
            guesser = await open_raw_tcp(port)
            for k in range(5):
                await guesser.send_all(hello("h1", "hider", token=f"guess{k}"))
            _, closed = await read_until_closed(guesser, 1)
            assert closed
            rover = await open_raw_tcp(port)
            await rover.send_all(hello("h1", "hider", token="sesame"))
            got, _ = await read_until_closed(rover, 0.1)
            assert b'"welcome"' in got
            assert [r.id for r in s.snapshot().rovers] == ["h1"]
            for line in (hello("h2", "seeker"), hello("h1", "hider", token="guess5")):
                other = await open_raw_tcp(port)
                await other.send_all(line)
                got, closed = await read_until_closed(other, 0.1)
                assert closed and b'"welcome"' not in got
            assert [r.id for r in s.snapshot().rovers] == ["h1"]

    run(main)
