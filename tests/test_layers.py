"""Both sides are layered (docs/ARCHITECTURE.md). In the C++ core a folder of csrc/ includes only its own
headers and those of the layers below it; on the Python side a package or module imports only its own
modules and those of the layers below it. These tests read every `#include "..."` line and every Python
import (inside functions too) and fail on one that runs upward or sideways, so the order written here is
the one the code keeps."""
from __future__ import annotations

import ast
import re
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
CSRC = REPO / "csrc"

# Bottom first; folders on the same line are one layer and do not include each other.
LAYERS = [
    ("base",),                  # parameter registry, plain types (EgoMotion, LaneModel, TrackState), errors, stopwatch
    ("geometry", "capture"),    # camera model, homographies, range; frame sources
    ("lanes",),                 # lane markings and the lane model
    ("cues",),                  # hypotheses, the detection stage a tracker asks, what both measure of a vehicle
    ("detect", "track"),        # detector parts; tracker parts (which ask the detectors only through cues/)
    ("road",),                  # the road-motion stage (features, road-plane homography, its Kalman filter)
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
    assert _violations([(Path("track/kalman/roi_search.cpp"), "detect/fuse_hypotheses.hpp")])
    assert _violations([(Path("detect/shadow/part.hpp"), "track/kalman/roi_search.hpp")])
    assert _violations([(Path("core/realtime_loop.hpp"), "include/headway.h")])
    assert not _violations([(Path("core/pipeline.hpp"), "base/types.hpp"), (Path("core/abi.cpp"), "include/headway.h")])


def test_the_configuration_includes_no_part_and_the_parts_registry_does_not_include_it_back():
    """Parts register their sections themselves (base/part_registry.hpp): core/config.hpp includes no detector or
    tracker part, nor core/parts.hpp (whose .cpp builds the parts from the configuration)."""
    of_config = [inc for src, inc in _includes() if src == Path("core/config.hpp")]
    assert of_config, "core/config.hpp: no include read"
    parts = [inc for inc in of_config if re.search(r"(detector|tracker)_\w+\.hpp$", inc) or inc == "core/parts.hpp"]
    assert not parts, f"core/config.hpp includes parts' headers: {parts}; register the part's section next to its factory"


# ---- the Python side ----

# Bottom first; units on the same line are one layer and do not import each other. A unit is a package or a
# module, and a module belongs to the longest unit that names it (app.eval.report, the `headway eval` command,
# sits above the fleet whose engine it runs on, while the rest of app.eval sits below the fleet).
PY_LAYERS = [
    ("app.contracts", "app._headway_core"),   # FCW levels, TTC sources, fault registry, key form; the built core
    ("app.core", "app.safe_yaml", "app.decode_errors", "app._build_core", "firmware_bridge"),
    ("app.output_files", "app.recording"),
    ("app.fcw", "app.tracks_file", "app.sim"),
    ("app.can",),
    ("app.config",),                          # the YAML file: reads the sections' schemas from the layers below
    ("app.config_check", "app.detect_images", "app.annotate", "app.train"),
    ("app.supervisor",),                      # the service: health, FCW, CAN and the MCU link around the core
    ("app.replay",),
    ("app.eval", "app.calibrate_drive"),
    ("app.fleet",),
    ("app.bench",),                           # measurements, above everything they measure
    # commands that gather parts from several layers below (each command's module adds its own parser)
    ("app.eval.report", "app.train.command", "app.demo", "app.calibrate", "app.config_command"),
    ("app.cli",),                             # the list of commands
]
PY_RANK = {unit: i for i, layer in enumerate(PY_LAYERS) for unit in layer}
PY_ROOTS = ("app", "firmware_bridge")


def _module_name(path: Path) -> str:
    parts = path.relative_to(REPO).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _is_module(name: str) -> bool:
    base = REPO.joinpath(*name.split("."))
    return base.with_suffix(".py").exists() or (base / "__init__.py").exists() or name == "app._headway_core"


def _targets(node: ast.AST, module: str, is_package: bool) -> list[str]:
    """The project modules an import statement names (`from app import config` names app.config)."""
    if isinstance(node, ast.Import):
        return [a.name for a in node.names]
    base = module if is_package else module.rpartition(".")[0]
    for _ in range(node.level - 1):
        base = base.rpartition(".")[0]
    name = node.module if not node.level else ".".join(p for p in (base, node.module) if p)
    subs = [f"{name}.{a.name}" for a in node.names if _is_module(f"{name}.{a.name}")]
    return subs if len(subs) == len(node.names) else [name] + subs


def py_unit(module: str):
    """The longest declared unit holding `module`; None when no unit does."""
    parts = module.split(".")
    for n in range(len(parts), 0, -1):
        if ".".join(parts[:n]) in PY_RANK:
            return ".".join(parts[:n])
    return None


def _imports():
    """(file, line, importing module, imported module) for every import of the project's own modules."""
    for root in PY_ROOTS:
        for path in sorted((REPO / root).rglob("*.py")):
            module = _module_name(path)
            for node in ast.walk(ast.parse(path.read_text(), str(path))):
                if isinstance(node, (ast.Import, ast.ImportFrom)):
                    for target in _targets(node, module, path.name == "__init__.py"):
                        if target.split(".")[0] in PY_ROOTS:
                            yield path.relative_to(REPO), node.lineno, module, target


def _py_violations(imports):
    bad = []
    for file, line, module, target in imports:
        here, there = py_unit(module), py_unit(target)
        if here is None or there is None:
            bad.append(f"{file}:{line}: {module} imports {target}: "
                       f"{module if here is None else target} has no layer in tests/test_layers.py PY_LAYERS")
        elif here != there and PY_RANK[there] >= PY_RANK[here]:
            bad.append(f"{file}:{line}: {module} ({here}, layer {PY_RANK[here]}) imports {target} "
                       f"({there}, layer {PY_RANK[there]})")
    return bad


def test_every_python_module_has_a_layer():
    # app/__init__.py is empty: importing any app module runs it, and it imports nothing back
    assert not (REPO / "app" / "__init__.py").read_text().strip(), "app/__init__.py must stay empty"
    missing = sorted({_module_name(p) for root in PY_ROOTS for p in (REPO / root).rglob("*.py")
                      if _module_name(p) != "app" and py_unit(_module_name(p)) is None})
    assert not missing, f"Python modules without a layer in tests/test_layers.py PY_LAYERS: {missing}"


def test_no_python_import_runs_upward_or_sideways():
    bad = _py_violations(_imports())
    assert not bad, "imports against the layer order:\n" + "\n".join(bad)


def test_the_python_check_catches_upward_and_sideways_imports():
    found = list(_imports())
    assert len(found) > 300, f"only {len(found)} imports found: the parser misses some"
    assert ("app/config.py" in {str(f) for f, *_ in found}
            and any(m == "app.bench.pipeline" and t == "app.bench.particles" for _, _, m, t in found)), \
        "`from app.bench import particles` is not read as an import of app.bench.particles"
    up = _py_violations([(Path("app/can/session.py"), 27, "app.can.session", "app.supervisor.faults")])
    assert up == ["app/can/session.py:27: app.can.session (app.can, layer 4) imports app.supervisor.faults "
                  "(app.supervisor, layer 7)"]
    assert _py_violations([(Path("app/fcw.py"), 1, "app.fcw", "app.sim.render")])            # sideways
    assert _py_violations([(Path("app/train/command.py"), 1, "app.train.command", "app.cli")])
    assert _py_violations([(Path("app/eval/compare.py"), 1, "app.eval.compare", "app.eval.report")])
    assert _py_violations([(Path("firmware_bridge/messages.py"), 1, "firmware_bridge.messages", "app.fcw")])
    assert not _py_violations([(Path("app/eval/report.py"), 1, "app.eval.report", "app.fleet.engine"),
                               (Path("app/can/session.py"), 1, "app.can.session", "app.can.messages"),
                               (Path("firmware_bridge/messages.py"), 1, "firmware_bridge.messages",
                                "app.contracts.fcw_level")])
