"""cffi_modules cannot live in pyproject.toml, so this stub carries it.

./headway.sh installs with HEADWAY_NO_EXT=1 and builds the extension incrementally itself
(app/_build_core.py); a plain `pip install .` or `pip wheel .` builds it here.
"""
import os

from setuptools import setup

if os.environ.get("HEADWAY_NO_EXT") == "1":
    setup()
else:
    os.environ["HEADWAY_CFFI_SETUP"] = "1"
    setup(cffi_modules=["app/_build_core.py:ffibuilder"])
