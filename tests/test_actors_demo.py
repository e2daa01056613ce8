"""``hideseek demo``: the runtime's showcase recovers from every injected fault."""

from __future__ import annotations

import argparse
import io

from tui import cmd_demo


def demo(*argv: str) -> tuple[int, str]:
    parser = argparse.ArgumentParser()
    cmd_demo.add_arguments(parser)
    out = io.StringIO()
    return cmd_demo.run(parser.parse_args(list(argv)), out), out.getvalue()


def test_demo_recovers_from_crash_hang_and_flood() -> None:
    """Each fault shows up, every actor is running again at the end, exit status 0."""
    rc, text = demo("--clock", "virtual", "--seed", "5")
    assert rc == 0
    assert "crash     pipeline/filter" in text
    assert "hung      pipeline/filter   watchdog 0.5 s" in text
    assert "accepted 16, the rest dropped" in text
    assert "restart   sensor" in text
    tree = text.split("--- tree at the end:")[1].split("---")[0]
    assert tree.count("running") == 4 and "stopped" not in tree


def test_demo_virtual_runs_repeat_bit_for_bit() -> None:
    """Same seed on the virtual clock: identical output, hash included."""
    assert demo("--clock", "virtual", "--seed", "9")[1] == demo("--clock", "virtual",
                                                                "--seed", "9")[1]


def test_demo_rejects_bad_arguments() -> None:
    assert demo("--duration", "1")[0] == 2
    assert demo("--rate", "-3")[0] == 2
