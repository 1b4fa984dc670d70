"""The C++ unit tests (doctest, tests/cpp/<csrc folder>/test_<unit>.cpp) built by ``python -m app._build_core
--tests`` and run here, so the suite's test command runs them too; a failing C++ check fails this test with
doctest's report. Every algorithm folder of csrc/ has at least one test file."""
from __future__ import annotations

import subprocess
from pathlib import Path

import pytest

from app import _build_core

ROOT = Path(__file__).resolve().parent.parent
ALGORITHM_FOLDERS = ("base", "capture", "cues", "detect", "fcw", "geometry", "lanes", "road", "track")


def test_every_algorithm_folder_has_cpp_unit_tests():
    missing = [d for d in ALGORITHM_FOLDERS if not list((ROOT / "tests" / "cpp" / d).glob("test_*.cpp"))]
    assert not missing, f"no tests/cpp/<folder>/test_*.cpp for {missing}"
    folders = {p.name for p in (ROOT / "csrc").iterdir() if p.is_dir()} - {"core", "include"}
    assert folders == set(ALGORITHM_FOLDERS), "a csrc folder was added or removed: list it in ALGORITHM_FOLDERS"


def test_cpp_unit_tests_pass():
    if not Path("/usr/include/doctest/doctest.h").exists():
        pytest.skip("doctest.h not found: install Debian's doctest-dev (./headway.sh does it)")
    binary = _build_core.build_tests()
    r = subprocess.run([str(binary), "--no-version"], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, f"C++ unit tests failed:\n{r.stdout}\n{r.stderr}"
    assert "Status: SUCCESS" in r.stdout, r.stdout
