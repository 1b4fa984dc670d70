"""The systemd units: `systemd-analyze verify` is clean on every unit, and install-service lays them out."""
from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from app.supervisor.install import UNITS, install, render_unit
from tests.conftest import REPO

UNIT_SUFFIXES = (".service", ".socket", ".timer", ".target", ".path", ".mount")


def test_every_unit_verifies_clean(tmp_path):
    if not shutil.which("systemd-analyze"):
        pytest.skip("systemd-analyze not installed (Debian package systemd)")
    units = [p for p in UNITS.iterdir() if p.suffix in UNIT_SUFFIXES]
    assert units, "no unit files in systemd/"
    # as installed: a checkout whose .venv/bin/headway is the console script of the environment running
    # the tests (verify checks that ExecStart is executable)
    install_dir = tmp_path / "headway"
    (install_dir / ".venv" / "bin").mkdir(parents=True)
    (install_dir / ".venv" / "bin" / "headway").symlink_to(Path(sys.executable).parent / "headway")
    for unit in units:
        out = tmp_path / unit.name
        out.write_text(render_unit(unit.read_text(), repo=install_dir))
        r = subprocess.run(["systemd-analyze", "verify", str(out)], capture_output=True, text=True, timeout=60)
        assert r.returncode == 0 and not (r.stdout + r.stderr).strip(), f"{unit.name}:\n{r.stdout}{r.stderr}"


def test_service_unit_has_the_hardening_and_watchdog():
    text = (UNITS / "headway.service").read_text()
    for line in ("Type=notify", "WatchdogSec=", "Restart=on-failure", "StartLimitBurst=", "NoNewPrivileges=yes",
                 "ProtectSystem=strict", "ProtectHome=yes", "PrivateTmp=yes",
                 "RestrictAddressFamilies=AF_UNIX AF_CAN AF_NETLINK", "DevicePolicy=closed",
                 "DeviceAllow=char-video4linux rw", "SystemCallFilter=@system-service", "StateDirectory=headway",
                 "User=headway"):
        assert line in text, line


def test_install_service_into_a_root(tmp_path):
    done = install(tmp_path, bench=True, enable=False)
    unit = (tmp_path / "etc/systemd/system/headway.service").read_text()
    assert f"ExecStart={REPO}/.venv/bin/headway service --config /etc/headway/config.yaml" in unit
    network = (tmp_path / "etc/systemd/network/80-headway-can0.network").read_text()
    assert "BitRate=500000" in network
    assert (tmp_path / "etc/systemd/network/80-headway-vcan0.netdev").read_text().count("Kind=vcan") == 1
    cfg = tmp_path / "etc/headway/config.yaml"
    assert "interface: socketcan" in cfg.read_text()
    # a second install keeps the operator's configuration and takes its bitrate
    cfg.write_text("can: {bitrate: 250000}\n")
    done = install(tmp_path, enable=False)
    assert cfg.read_text() == "can: {bitrate: 250000}\n" and any("kept" in d for d in done)
    assert "BitRate=250000" in (tmp_path / "etc/systemd/network/80-headway-can0.network").read_text()
