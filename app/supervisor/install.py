"""`headway install-service`: put Headway into systemd on this machine.

Writes the unit (with this checkout's path), the systemd-networkd set-up of can0 at the configured
bitrate (and vcan0 with --bench), /etc/headway/config.yaml if there is none (never overwriting one),
creates the `headway` system user, then reloads systemd and enables the unit. --root installs into
a folder instead (packaging, tests) and skips what needs a running system.
"""
from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

from app import config as configuration
from app.output_files import write_whole

REPO = Path(__file__).resolve().parent.parent.parent
UNITS = REPO / "systemd"


def render_unit(text: str, repo: Path = REPO, bitrate: int = 500000) -> str:
    return text.replace("@HEADWAY_DIR@", str(repo)).replace("@CAN_BITRATE@", str(bitrate))


def install(root: Path, bench: bool = False, enable: bool = True) -> list[str]:
    done = []
    etc = root / "etc"
    config_path = etc / "headway" / "config.yaml"
    cfg = configuration.load(config_path if config_path.exists() else None)
    files = {
        "headway.service": etc / "systemd" / "system" / "headway.service",
        "headway-can0.network": etc / "systemd" / "network" / "80-headway-can0.network",
    }
    if bench:
        files["headway-vcan0.netdev"] = etc / "systemd" / "network" / "80-headway-vcan0.netdev"
        files["headway-vcan0.network"] = etc / "systemd" / "network" / "80-headway-vcan0.network"
    for name, dest in files.items():
        dest.parent.mkdir(parents=True, exist_ok=True)
        write_whole(dest, render_unit((UNITS / name).read_text(), bitrate=cfg["can"]["bitrate"]))
        done.append(f"wrote {dest}")
    if not config_path.exists():
        config_path.parent.mkdir(parents=True, exist_ok=True)
        text = configuration.default_yaml().replace("  interface: virtual", "  interface: socketcan")
        text = text.replace("  channel: vcan0", "  channel: can0")
        # whole or not at all: a configuration cut short would be kept by every later install
        write_whole(config_path, text)
        done.append(f"wrote {config_path} (edit the camera: and can: sections for your car)")
    else:
        done.append(f"kept {config_path}")
    if root == Path("/"):
        if shutil.which("useradd") and subprocess.run(["id", "headway"], capture_output=True).returncode != 0:
            subprocess.run(["useradd", "--system", "--no-create-home", "--shell", "/usr/sbin/nologin",
                            "--groups", "video,dialout", "headway"], check=True)
            done.append("created the system user headway (groups video, dialout)")
        if enable:
            subprocess.run(["systemctl", "daemon-reload"], check=True)
            subprocess.run(["systemctl", "enable", "headway.service"], check=True)
            subprocess.run(["systemctl", "enable", "systemd-networkd.service"], check=False)
            done.append("enabled headway.service (start it now with: systemctl start headway)")
    return done


def add_parser(subparsers) -> None:
    s = subparsers.add_parser("install-service", help="install the systemd unit, the CAN set-up and /etc/headway/config.yaml")
    s.add_argument("--root", default="/", help="install into this root folder (default /; for packaging and tests)")
    s.add_argument("--bench", action="store_true", help="also set up a virtual CAN interface vcan0")
    s.add_argument("--no-enable", action="store_true", help="do not run systemctl (no daemon-reload, no enable)")
    s.set_defaults(run=run)


def run(args) -> int:
    for line in install(Path(args.root), bench=args.bench, enable=not args.no_enable):
        print(line)
    return 0
