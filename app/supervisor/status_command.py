"""`headway status`: the running service's health from its status file, for a person at a shell; the
exit code says whether the service runs (0) or not (3: stopped or unknown), as systemctl's does."""
from __future__ import annotations

import json
import os

from app import config as configuration
from app.supervisor.status_file import STOPPED, UNKNOWN, StatusFileError, assess, format_status, read_status


def add_parser(subparsers) -> None:
    s = subparsers.add_parser("status", help="the running service's health, for a person at a shell")
    s.add_argument("--file", default=None, help="status file (default: service.status_file of --config)")
    s.add_argument("--config", default="/etc/headway/config.yaml", help="configuration YAML")
    s.add_argument("--json", action="store_true", help="print the raw JSON")
    s.set_defaults(run=run)


def run(args) -> int:
    path = args.file
    if path is None:
        path = os.environ.get("HEADWAY_STATUS_FILE")
    if path is None:
        cfg = configuration.load(args.config if os.path.exists(args.config) else None)
        path = cfg["service"]["status_file"]
    try:
        st = read_status(path)
    except StatusFileError as exc:
        print(f"state: {UNKNOWN}\nheadway: {exc}")
        return 3
    print(json.dumps(st, indent=1) if args.json and st else format_status(st, path))
    if st is None:
        return 1
    # 0 while the service runs (ok, degraded, fault: its own words); 3 when it does not, as systemctl's
    # "not running": stopped, or unknown (gone, stale, future or malformed time stamp)
    return 0 if assess(st)[0] not in (UNKNOWN, STOPPED) else 3
