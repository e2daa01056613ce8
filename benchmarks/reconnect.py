"""Seconds from a restarted server listening to an attached rover's welcome (kill -9).

Runs the real commands as a person would: ``hideseek serve`` (hider and
seeker simulated in it, the mapper attached over TCP, a database file) and
``hideseek rover --role mapper --link tcp:...``; starts mapping, lets it run
``--mapping-s`` seconds, kills the server with SIGKILL, starts it again at once
on the same database and port, and times, on the wall clock of this process,
from the restarted server's ``listening on`` line to its ``hello`` line for the
mapper (the hello it answers with the welcome). Repeated ``--trials`` times;
prints each figure and the median, and as JSON with ``--json``.

Run: ``python -m benchmarks.reconnect [--trials 5] [--mapping-s 8]``.
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time

ROOT = pathlib.Path(__file__).resolve().parent.parent


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class _Lines:
    """A process's stdout lines, each with the wall time it was read [s]."""

    def __init__(self, proc: subprocess.Popen) -> None:
        self.lines: list[tuple[float, str]] = []
        self._cond = threading.Condition()
        threading.Thread(target=self._read, args=(proc,), daemon=True).start()

    def _read(self, proc: subprocess.Popen) -> None:
        for line in proc.stdout:  # type: ignore[union-attr]
            with self._cond:
                self.lines.append((time.perf_counter(), line.rstrip("\n")))
                self._cond.notify_all()

    def wait_for(self, text: str, after: int = 0, timeout: float = 60.0) -> tuple[int, float]:
        """Index and time of the first line from ``after`` on containing ``text``."""
        deadline = time.perf_counter() + timeout
        with self._cond:
            while True:
                for i in range(after, len(self.lines)):
                    if text in self.lines[i][1]:
                        return i, self.lines[i][0]
                left = deadline - time.perf_counter()
                if left <= 0:
                    raise TimeoutError(f"no line with {text!r} in {timeout:g} s")
                self._cond.wait(left)


def _serve(port: int, db: str) -> tuple[subprocess.Popen, _Lines]:
    proc = subprocess.Popen(
        [sys.executable, "-m", "tui.cli", "serve", "--listen", f"tcp:127.0.0.1:{port}",
         "--rover", "mapper=tcp", "--rover", "hider=sim", "--rover", "seeker=sim",
         "--scenario", "empty", "--db", db],
        cwd=ROOT, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
        text=True, bufsize=1)
    return proc, _Lines(proc)


def trial(mapping_s: float) -> float:
    """One kill -9 and restart; returns seconds from listening to the mapper's hello."""
    port = _free_port()
    with tempfile.TemporaryDirectory() as tmp:
        db = os.path.join(tmp, "game.db")
        server, out = _serve(port, db)
        rover = subprocess.Popen(
            [sys.executable, "-m", "tui.cli", "rover", "--role", "mapper", "--scenario", "empty",
             "--link", f"tcp:127.0.0.1:{port}"],
            cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        try:
            out.wait_for("hello      mapper")
            server.stdin.write("start_mapping\n")  # type: ignore[union-attr]
            server.stdin.flush()  # type: ignore[union-attr]
            out.wait_for("phase=mapping")
            time.sleep(mapping_s)
            server.send_signal(signal.SIGKILL)
            server.wait()
            server, out = _serve(port, db)
            i, listening = out.wait_for("listening on tcp:")
            _, hello = out.wait_for("hello      mapper", after=i)
            return hello - listening
        finally:
            for proc in (rover, server):
                proc.send_signal(signal.SIGINT)
                try:
                    proc.wait(timeout=10)
                except subprocess.TimeoutExpired:
                    proc.kill()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=5)
    parser.add_argument("--mapping-s", type=float, default=8.0,
                        help="seconds of mapping before the kill (default 8)")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    figures = []
    for k in range(args.trials):
        s = trial(args.mapping_s)
        figures.append(s)
        if not args.json:
            print(f"trial {k + 1}: welcomed {s:.2f} s after the server listened", flush=True)
    median = statistics.median(figures)
    if args.json:
        print(json.dumps({"trials": figures, "median_s": median}))
    else:
        print(f"median of {len(figures)}: {median:.2f} s")


if __name__ == "__main__":
    main()
