"""The C++ core is layered (docs/ARCHITECTURE.md): a folder of csrc/ includes only its own headers and those
of the layers below it. This test reads every `#include "..."` line and fails on one that runs upward or
sideways, so the order written here is the one the code keeps."""
from __future__ import annotations

import re
from pathlib import Path

CSRC = Path(__file__).resolve().parent.parent / "csrc"

# Bottom first; folders on the same line are one layer and do not include each other.
LAYERS = [
    ("base",),                  # parameter registry, plain types (EgoMotion, LaneModel, TrackState), errors, stopwatch
    ("geometry", "capture"),    # camera model, homographies, range; frame sources
    ("lanes",),                 # lane markings and the lane model
    ("detect",),                # detector parts and what they are built from
    ("road",),                  # the road-motion stage (features, road-plane homography, its Kalman filter)
    ("track",),                 # tracker parts
    ("fcw",),                   # lead selection
    ("core",),                  # config, composition, pipeline, real-time loop, ABI
]
RANK = {folder: i for i, layer in enumerate(LAYERS) for folder in layer}
INCLUDE = re.compile(r'^\s*#\s*include\s+"([^"]+)"', re.M)


def _includes():
    for path in sorted(CSRC.rglob("*")):
        if path.suffix in (".hpp", ".cpp", ".h"):
            for m in INCLUDE.finditer(path.read_text()):
                yield path.relative_to(CSRC), m.group(1)


def test_every_folder_of_csrc_has_a_layer():
    folders = {p.name for p in CSRC.iterdir() if p.is_dir()} - {"include"}
    assert folders <= set(RANK), f"csrc folders without a layer in tests/test_layers.py: {sorted(folders - set(RANK))}"


def _violations(pairs):
    bad = []
    for src, inc in pairs:
        here, there = src.parts[0], inc.split("/")[0]
        if there == "include":
            if src != Path("core/abi.cpp"):
                bad.append(f"{src} includes {inc}: only core/abi.cpp speaks the C ABI")
            continue
        if "/" not in inc:  # a sibling in the same folder
            continue
        if there not in RANK:
            bad.append(f"{src} includes {inc}, a folder with no layer")
        elif there != here and RANK[there] >= RANK[here]:
            bad.append(f"{src} ({here}, layer {RANK[here]}) includes {inc} ({there}, layer {RANK[there]})")
    return bad


def test_no_include_runs_upward_or_sideways():
    bad = _violations(_includes())
    assert not bad, "includes against the layer order:\n" + "\n".join(bad)


def test_the_check_catches_upward_sideways_and_abi_includes():
    assert list(_includes()), "no include found: the parser reads nothing"
    assert _violations([(Path("base/types.hpp"), "core/config.hpp")])
    assert _violations([(Path("track/tracker.hpp"), "fcw/lead_selection.hpp")])
    assert _violations([(Path("capture/frame_source.hpp"), "geometry/camera.hpp")])
    assert _violations([(Path("core/realtime_loop.hpp"), "include/headway.h")])
    assert not _violations([(Path("core/pipeline.hpp"), "base/types.hpp"), (Path("core/abi.cpp"), "include/headway.h")])
