#!/usr/bin/env bash
# One entry point on a fresh Debian 12 machine: installs what Headway needs (once), builds the C++
# core (incrementally), then runs the command.
#   ./headway.sh demo            the main job: render a scenario, run the pipeline, write ./headway-demo/
#   ./headway.sh test [ARGS]     the whole test suite (pytest ARGS)
#   ./headway.sh ARGS            any `headway` subcommand, e.g. ./headway.sh replay drive.mp4
# A second run with nothing changed only checks timestamps (a second or two).
set -euo pipefail
cd "$(dirname "$(readlink -f "$0")")"

APT_PACKAGES=(g++ pkg-config libopencv-dev libjpeg-dev libeigen3-dev nlohmann-json3-dev doctest-dev python3-dev python3-venv libffi-dev systemd)
VENV=.venv

missing=()
for p in "${APT_PACKAGES[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "ok installed" || missing+=("$p")
done
if ((${#missing[@]})); then
    echo "headway: installing Debian packages: ${missing[*]}" >&2
    SUDO=""
    if [ "$(id -u)" != 0 ]; then
        command -v sudo >/dev/null || { echo "headway: run as root or install: ${missing[*]}" >&2; exit 1; }
        SUDO=sudo
    fi
    $SUDO apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi

if [ ! -x "$VENV/bin/python" ]; then
    echo "headway: creating the virtual environment $VENV" >&2
    python3 -m venv "$VENV"
fi
# Reinstall the Python dependencies only when the packaging files change.
stamp=$(cat pyproject.toml setup.py | sha256sum | cut -d' ' -f1)
if [ "$(cat "$VENV/.headway-deps" 2>/dev/null)" != "$stamp" ]; then
    echo "headway: installing Python dependencies" >&2
    # The extension is built below, incrementally; the editable install only brings the dependencies
    # and the `headway` console script. Its chatter goes to a log, shown only if it fails.
    if ! { "$VENV/bin/pip" install -q --upgrade pip && HEADWAY_NO_EXT=1 "$VENV/bin/pip" install -q -e ".[test]"; } \
        > "$VENV/pip.log" 2>&1; then
        cat "$VENV/pip.log" >&2
        echo "headway: installing the Python dependencies failed (log above, also in $VENV/pip.log)" >&2
        exit 1
    fi
    echo "$stamp" > "$VENV/.headway-deps"
fi
"$VENV/bin/python" -m app._build_core >/dev/null

if [ "${1:-}" = test ]; then
    shift
    exec "$VENV/bin/python" -m pytest "$@"
fi
exec "$VENV/bin/headway" "$@"
