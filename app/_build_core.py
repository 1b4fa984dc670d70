"""Builds the C++ core into the cffi extension ``app._headway_core``.

The C++ sources under ``csrc/`` are compiled to objects in ``build/obj`` (only those whose source or
included headers changed, two at a time), then cffi links them with a small stub generated from the
declarations in ``csrc/include/headway.h``. Run directly (``python -m app._build_core``) for an
incremental rebuild, or through setup.py's ``cffi_modules`` when pip builds a wheel.

``python -m app._build_core --tests`` also builds the C++ unit tests: the doctest sources under ``tests/cpp/``
compiled to ``build/cpp_tests/obj`` the same incremental way and linked with the core's objects into
``build/cpp_tests/headway_cpp_tests`` (tests/test_cpp_units.py builds and runs it).
"""
from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
import sysconfig
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import cffi

ROOT = Path(__file__).resolve().parent.parent
CSRC = ROOT / "csrc"
HEADER = CSRC / "include" / "headway.h"
BUILD = ROOT / "build"
OBJ = BUILD / "obj"
MODULE = "app._headway_core"
# -O3: GCC 12 vectorises the per-pixel loops (Harris, row filter, differences) only at -O3; measured
# 5.3 -> 4.7 ms per 640x480 frame of the parallax preset (docs/PERFORMANCE.md). No -march: the objects must
# run on any x86-64. No -ffast-math. The parallax preset's particle filter amplifies last-bit differences, so its
# synthetic scores moved within their usual spread (MOTA 0.338 -> 0.339).
CXXFLAGS = ["-std=c++17", "-O3", "-fPIC", "-Wall", "-Wextra", "-Wno-unused-parameter", "-g0"]
CPP_TESTS = ROOT / "tests" / "cpp"
TESTS_BUILD = BUILD / "cpp_tests"
TESTS_BINARY = TESTS_BUILD / "headway_cpp_tests"
# Linked beside OpenCV: the image folder source decodes JPEGs with libjpeg itself to count its warnings
# (csrc/capture/jpeg_decode.cpp; Debian's libjpeg-dev).
EXTRA_LIBS = ["jpeg"]


def pkg_config(*args: str) -> list[str]:
    try:
        out = subprocess.run(["pkg-config", *args, "opencv4"], check=True, capture_output=True, text=True).stdout
    except (OSError, subprocess.CalledProcessError) as exc:
        raise SystemExit(
            "pkg-config cannot find opencv4: install Debian's libopencv-dev (./headway.sh does it)"
        ) from exc
    return out.split()


def cdef_text() -> str:
    """The plain declarations between the HW_CDEF markers (cffi cannot parse #ifdef / extern "C")."""
    text = HEADER.read_text()
    m = re.search(r"/\* HW_CDEF_BEGIN \*/(.*)/\* HW_CDEF_END \*/", text, re.S)
    if not m:
        raise SystemExit(f"{HEADER}: HW_CDEF_BEGIN/HW_CDEF_END markers missing")
    return m.group(1)


def sources(root: Path = CSRC) -> list[Path]:
    return sorted(root.rglob("*.cpp"))


def object_of(src: Path, root: Path = CSRC, obj_dir: Path = OBJ) -> Path:
    return obj_dir / (str(src.relative_to(root)).replace(os.sep, "__") + ".o")


def is_stale(src: Path, obj: Path) -> bool:
    """An object is stale if missing or older than its source or any header it included when it was built."""
    if not obj.exists():
        return True
    t = obj.stat().st_mtime
    dep = obj.with_suffix(".d")
    if not dep.exists():
        return True
    deps = dep.read_text().replace("\\\n", " ").split(":", 1)[-1].split()
    return any(not Path(d).exists() or Path(d).stat().st_mtime > t for d in deps + [str(src)])


def compile_objects(jobs: int = 2, root: Path = CSRC, obj_dir: Path = OBJ) -> list[Path]:
    """Compiles the stale sources under ``root`` into ``obj_dir``; returns every object, in source order."""
    obj_dir.mkdir(parents=True, exist_ok=True)
    stamp = obj_dir / "flags"
    cflags = pkg_config("--cflags") + ["-I/usr/include/eigen3", f"-I{CSRC}"]
    srcs = sources(root)
    # objects compiled with other flags are all stale (timestamps alone would keep them)
    flags = " ".join(CXXFLAGS + cflags)
    same_flags = stamp.exists() and stamp.read_text() == flags
    stale = [s for s in srcs if not same_flags or is_stale(s, object_of(s, root, obj_dir))]

    def build(src: Path) -> tuple[Path, str]:
        obj = object_of(src, root, obj_dir)
        cmd = ["g++", *CXXFLAGS, *cflags, "-MMD", "-MF", str(obj.with_suffix(".d")), "-c", str(src), "-o", str(obj)]
        r = subprocess.run(cmd, capture_output=True, text=True)
        if r.returncode != 0:
            obj.unlink(missing_ok=True)
        return src, (r.stderr if r.returncode != 0 else "")

    failed = []
    if stale:
        print(f"compiling {len(stale)} of {len(srcs)} C++ sources under {root.relative_to(ROOT)}", file=sys.stderr)
        with ThreadPoolExecutor(max_workers=jobs) as pool:
            for src, err in pool.map(build, stale):
                if err:
                    failed.append(f"{src.relative_to(ROOT)}:\n{err}")
    if failed:
        raise SystemExit("C++ build failed:\n" + "\n".join(failed))
    stamp.write_text(flags)
    return [object_of(s, root, obj_dir) for s in srcs]


def make_ffibuilder(objects: list[Path]) -> cffi.FFI:
    ffi = cffi.FFI()
    ffi.cdef(cdef_text())
    libs = [a[2:] for a in pkg_config("--libs") if a.startswith("-l")]
    libdirs = [a[2:] for a in pkg_config("--libs") if a.startswith("-L")]
    ffi.set_source(
        MODULE,
        '#include "include/headway.h"',
        source_extension=".cpp",
        include_dirs=[str(CSRC)],
        extra_objects=[str(o) for o in objects],
        libraries=libs + EXTRA_LIBS + ["stdc++"],
        library_dirs=libdirs,
        extra_compile_args=["-O2", "-g0"],
    )
    return ffi


def module_path() -> Path:
    return ROOT / "app" / ("_headway_core" + sysconfig.get_config_var("EXT_SUFFIX"))


def build_inplace(jobs: int = 2) -> Path:
    """Incremental build; returns the extension path. Links only when an object or the header changed."""
    objects = compile_objects(jobs)
    target = module_path()
    newest = max([o.stat().st_mtime for o in objects] + [HEADER.stat().st_mtime, Path(__file__).stat().st_mtime])
    if target.exists() and target.stat().st_mtime >= newest:
        return target
    tmp = BUILD / "cffi"
    built = Path(make_ffibuilder(objects).compile(tmpdir=str(tmp), verbose=False))
    # copy then rename: a process that has the old module loaded keeps its (unlinked) file intact;
    # copying over it in place crashes such processes
    tmp_target = target.with_name(target.name + ".tmp")
    shutil.copy2(built, tmp_target)
    os.replace(tmp_target, target)
    return target


# setup.py's cffi_modules imports this file and takes `ffibuilder`; building the objects here keeps a
# wheel build working the same way as the incremental build.
if os.environ.get("HEADWAY_CFFI_SETUP") == "1":
    ffibuilder = make_ffibuilder(compile_objects())

def build_tests(jobs: int = 2) -> Path:
    """Incremental build of the C++ unit tests (doctest, Debian's doctest-dev) linked with the core's objects;
    returns the binary's path. Links only when an object changed."""
    if not Path("/usr/include/doctest/doctest.h").exists():
        raise SystemExit("doctest.h not found: install Debian's doctest-dev (./headway.sh does it)")
    core = compile_objects(jobs)
    tests = compile_objects(jobs, CPP_TESTS, TESTS_BUILD / "obj")
    objects = core + tests
    if TESTS_BINARY.exists() and TESTS_BINARY.stat().st_mtime >= max(o.stat().st_mtime for o in objects):
        return TESTS_BINARY
    cmd = ["g++", "-o", str(TESTS_BINARY), *map(str, objects), *pkg_config("--libs"),
           *(f"-l{lib}" for lib in EXTRA_LIBS), "-pthread"]
    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode != 0:
        raise SystemExit("linking the C++ unit tests failed:\n" + r.stderr)
    return TESTS_BINARY


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description="Incremental build of the C++ core (and its unit tests).")
    parser.add_argument("--tests", action="store_true", help="also build build/cpp_tests/headway_cpp_tests")
    args = parser.parse_args()
    print(build_inplace())
    if args.tests:
        print(build_tests())
