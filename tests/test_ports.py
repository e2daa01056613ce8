"""``hideseek ports``: kernel names with their stable by-id names beside them."""

from __future__ import annotations

import argparse
import json
import os
from types import SimpleNamespace

from serial.tools import list_ports

from tui import cmd_ports


def _fake_machine(tmp_path, monkeypatch) -> tuple[str, str]:
    """Two adapters, ttyUSB0 (with a by-id name) and ttyUSB1 (without); udev's folder."""
    dev = tmp_path / "dev"
    by_id = tmp_path / "by-id"
    dev.mkdir()
    by_id.mkdir()
    for name in ("ttyUSB0", "ttyUSB1"):
        (dev / name).touch()
    stable = by_id / "usb-FTDI_FT232R_USB_UART_A10K5ZQ1-if00-port0"
    os.symlink("../dev/ttyUSB0", stable)
    (by_id / "not-a-link").touch()
    monkeypatch.setattr(cmd_ports, "BY_ID", str(by_id))
    monkeypatch.setattr(list_ports, "comports", lambda: [
        SimpleNamespace(device=str(dev / n), description=f"FT232R {n}", hwid="USB VID:PID=0403")
        for n in ("ttyUSB1", "ttyUSB0")])
    return str(dev / "ttyUSB0"), str(stable)


def test_stable_names_lead_to_their_kernel_device(tmp_path, monkeypatch) -> None:
    device, stable = _fake_machine(tmp_path, monkeypatch)
    assert cmd_ports.stable_names(cmd_ports.BY_ID) == {os.path.realpath(device): [stable]}
    assert cmd_ports.stable_names(str(tmp_path / "nowhere")) == {}


def test_ports_shows_the_by_id_name_beside_the_kernel_name(tmp_path, monkeypatch,
                                                             capsys) -> None:
    device, stable = _fake_machine(tmp_path, monkeypatch)
    assert cmd_ports.run(argparse.Namespace(json=True)) == 0
    rows = json.loads(capsys.readouterr().out)
    assert [(r["device"], r["by_id"]) for r in rows] == [(device, [stable]),
                                                         (device[:-1] + "1", [])]
    assert cmd_ports.run(argparse.Namespace(json=False)) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith(device) and lines[1].split() == ["stable", "name:", stable]
    assert lines[2].startswith(device[:-1] + "1")
    assert "--rover ID=serial:NAME" in lines[-1]
