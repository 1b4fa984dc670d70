"""`headway`: the command line. Each command's module adds its own parser and runs it (`add_parser`,
`run`); this file only lists them and turns every expected failure into one clear line on stderr and a
non-zero exit."""
from __future__ import annotations

import argparse
import importlib
import os
import sys
from typing import Optional

# OpenCV and FFmpeg print their own warnings (a file that is not a video, a camera index that does not
# open) before ours says the same in one line; keep only their errors. Set before the commands' modules
# import OpenCV, which reads these once.
os.environ.setdefault("OPENCV_LOG_LEVEL", "ERROR")
os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "-8")

from app.config import ConfigFileError, error_line  # noqa: E402
from app.core import ConfigError, CoreError  # noqa: E402

# Each command's module, in the order `headway --help` lists them; the module adds the command's parser
# (`add_parser`) and runs it (`run`). A command imports only its own module: together they import Dask,
# SciPy, pandas and the training code, ~4 s that `headway status` in a car must not wait for.
COMMANDS = {
    "demo": "app.demo",
    "sim": "app.sim.command",
    "replay": "app.replay",
    "detect": "app.detect_images",
    "run": "app.supervisor.service",       # `run` and `service`: one module adds both
    "service": "app.supervisor.service",
    "status": "app.supervisor.status_command",
    "install-service": "app.supervisor.install",
    "bench": "app.bench.pipeline",
    "eval": "app.eval.report",
    "fleet": "app.fleet.run",
    "train": "app.train.command",
    "calibrate": "app.calibrate",
    "config": "app.config_command",
}


def build_parser(command: Optional[str] = None) -> argparse.ArgumentParser:
    """The parser of every command, or only of `command` (a name in COMMANDS) when that is the one given."""
    p = argparse.ArgumentParser(prog="headway", description="Camera-based vehicle detection, tracking and "
                                                            "forward-collision warning.")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")
    modules = [COMMANDS[command]] if command in COMMANDS else list(dict.fromkeys(COMMANDS.values()))
    for module in modules:
        importlib.import_module(module).add_parser(sub)
    return p


def main(argv=None) -> int:
    args = None
    try:
        argv = sys.argv[1:] if argv is None else list(argv)
        args = build_parser(argv[0] if argv else None).parse_args(argv)
        if args.command == "config":
            # a check opens models and sources: OpenCV's own log lines would come before (and say less than) ours
            os.environ["OPENCV_LOG_LEVEL"] = "SILENT"
        return args.run(args)
    except (ConfigFileError, ConfigError) as exc:
        # one mapping: every configuration error is exit 2, one line, its file, the key's line, the key
        print(f"headway: configuration error: {error_line(exc, getattr(args, 'config', None) or getattr(args, 'file', None))}",
              file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130
    except (CoreError, OSError, RuntimeError, ValueError) as exc:
        # every expected failure (bad source, scenario, image, ...) as one line
        print(f"headway: error: {' '.join(str(exc).split())}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
