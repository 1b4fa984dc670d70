"""`headway config check FILE | default | doc`: a configuration checked by opening what the service opens
(app/config_check.py), or the documented defaults as YAML or as the markdown of docs/CONFIG.md."""
from __future__ import annotations

import sys

from app import config as configuration
from app.config_check import problems


def add_parser(subparsers) -> None:
    s = subparsers.add_parser("config", help="check a configuration file, or print the documented defaults")
    cs = s.add_subparsers(dest="action", required=True, metavar="ACTION")
    c = cs.add_parser("check", help="validate FILE and open what the service opens (models, output files, CAN "
                                    "interface, source); prints the first problem in one line and exits 2")
    c.add_argument("file")
    c.add_argument("--skip-absent-devices", action="store_true",
                   help="do not fail on a camera that is not on this machine (checking a car's file elsewhere)")
    cs.add_parser("default", help="print the default configuration with every key documented")
    cs.add_parser("doc", help="print the configuration reference as markdown (docs/CONFIG.md)")
    s.set_defaults(run=run)


def run(args) -> int:
    if args.action == "default":
        print(configuration.default_yaml())
        return 0
    if args.action == "doc":
        print(configuration.markdown())
        return 0
    cfg = configuration.load(args.file)
    # everything that would stop the service, opened as the service opens it; the first problem is the line
    found = problems(cfg, skip_absent_devices=args.skip_absent_devices)
    if found:
        print(f"headway: configuration error: {configuration.error_line(found[0], args.file)}", file=sys.stderr)
        return 2
    print(f"{args.file}: ok")
    return 0
