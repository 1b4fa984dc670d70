"""One configuration key as the registry describes it: default, type, range or choices, and a doc
("unit; what; why this default"). Every section of the supervisor (config, fcw, health, can) declares
its keys with this, in the same form as the core's own (`app.core.core_schema()`)."""
from __future__ import annotations

from typing import Any, Optional

_TYPES = {bool: "bool", int: "int", float: "float", str: "str"}


def key(default: Any, doc: str, min: Any = None, max: Any = None, choices: Optional[str] = None,
        type: Optional[str] = None) -> dict:
    d = {"default": default, "type": type or _TYPES[default.__class__], "doc": doc}
    if min is not None:
        d["min"], d["max"] = min, max
    if choices:
        d["choices"] = choices
    return d
