"""Loading a YAML configuration within bounds, and quoting values in error messages briefly.

Numbers and booleans are read as YAML 1.2's core schema says, not as YAML 1.1 (PyYAML's own): `12:30:00`
is a string, not the sexagesimal 45000; `yes`, `no`, `on`, `off` are strings, not booleans; `012` is 12,
not octal 10; dates stay strings. PyYAML's libyaml parser is kept and only its resolver (which tag a plain
scalar gets) is replaced, since the resolver runs in Python for both parsers (docs/decisions.md).

PyYAML's safe loader builds no objects, but it accepts what a configuration never needs and a hostile
or broken file can abuse: aliases that expand a few hundred bytes into gigabytes once printed (the
"billion laughs"), nesting deep enough to exhaust the stack, and duplicate keys, of which the last
silently wins (`camera:` written twice replaces the first section). ``load_yaml`` refuses all of them
with one short line; ``short`` quotes any value in at most ``QUOTE_CHARS`` characters without ever
building its full text.
"""
from __future__ import annotations

import re
import reprlib
from typing import Any

import yaml

MAX_BYTES = 1 << 20   # a configuration is a few kB; 1 MB leaves room for comments and bounds memory
MAX_ALIASES = 100     # anchors are a convenience for a few shared values, not a data structure
MAX_DEPTH = 20        # sections are 2 levels deep; any value is a scalar
QUOTE_CHARS = 80      # a value is quoted in an error message to at most this many characters
QUOTE_NESTING = 2     # and nested containers are shown this many deep

_repr = reprlib.Repr()
_repr.maxstring = _repr.maxother = QUOTE_CHARS
_repr.maxlist = _repr.maxtuple = _repr.maxdict = _repr.maxset = 4
_repr.maxlevel = QUOTE_NESTING


class YamlLimitError(ValueError):
    """A YAML text that is malformed or outside the bounds; the message is one short line."""


def short(value: Any) -> str:
    """``repr(value)`` cut to about QUOTE_CHARS characters, in time and memory bounded whatever the value."""
    text = _repr.repr(value)
    return text if len(text) <= QUOTE_CHARS + 3 else text[:QUOTE_CHARS] + "..."


def short_name(name: Any) -> str:
    """A key or section name as written (no quotes), cut to QUOTE_CHARS characters."""
    text = name if isinstance(name, str) else short(name)
    return text if len(text) <= QUOTE_CHARS + 3 else text[:QUOTE_CHARS] + "..."


def short_path(path: Any, chars: int = QUOTE_CHARS) -> str:
    """A file path as written, its end kept (the file's name) when it is longer than ``chars`` characters;
    a NUL or other control character shown escaped."""
    text = str(path)
    text = text if text.isprintable() else repr(text)[1:-1]
    return text if len(text) <= chars + 3 else "..." + text[-chars:]


# libyaml's parser where PyYAML has it (the PyPI wheels do): 10-50x faster than the pure-Python one; the
# bounds below hold for both (checked on the text before either sees it, and again while composing).
_Base = getattr(yaml, "CSafeLoader", yaml.SafeLoader)
MAX_INDENT = 80       # characters of leading blanks on a line: with the limits below, nesting stays < 150


class _Yaml12Loader(_Base):
    """libyaml's parser with YAML 1.2's core-schema resolver (null, bool, int, float; no timestamps,
    no sexagesimal numbers, no yes/no/on/off booleans)."""

    yaml_implicit_resolvers: dict = {}   # none of YAML 1.1's; those of 1.2 are added below

    def construct_yaml_int(self, node):
        text = self.construct_scalar(node)
        sign, digits = (-1, text[1:]) if text[0] == "-" else (1, text.lstrip("+"))
        if digits.startswith("0o"):
            return sign * int(digits[2:], 8)
        if digits.startswith("0x"):
            return sign * int(digits[2:], 16)
        return sign * int(digits, 10)


_Yaml12Loader.add_constructor("tag:yaml.org,2002:int", _Yaml12Loader.construct_yaml_int)
for _tag, _pattern, _first in (
        ("null", r"^(?:~|null|Null|NULL|)$", "~nN"),
        ("bool", r"^(?:true|True|TRUE|false|False|FALSE)$", "tTfF"),
        ("int", r"^(?:[-+]?[0-9]+|0o[0-7]+|0x[0-9a-fA-F]+)$", "-+0123456789"),
        ("float", r"^(?:[-+]?(?:\.[0-9]+|[0-9]+(?:\.[0-9]*)?)(?:[eE][-+]?[0-9]+)?|[-+]?\.(?:inf|Inf|INF)"
                  r"|\.(?:nan|NaN|NAN))$", "-+0123456789."),
        ("merge", r"^(?:<<)$", "<")):
    _Yaml12Loader.add_implicit_resolver(f"tag:yaml.org,2002:{_tag}", re.compile(_pattern), list(_first) +
                                        ([""] if _tag == "null" else []))


class _BoundedLoader(_Yaml12Loader):
    def __init__(self, stream: str):
        super().__init__(stream)
        self._aliases = 0
        self._depth = 0

    def compose_node(self, parent, index):
        if self.check_event(yaml.AliasEvent):
            self._aliases += 1
            if self._aliases > MAX_ALIASES:
                mark = self.peek_event().start_mark
                raise YamlLimitError(f"line {mark.line + 1}: more than {MAX_ALIASES} aliases (*name); write the "
                                     f"values out")
        self._depth += 1
        try:
            if self._depth > MAX_DEPTH:
                mark = self.peek_event().start_mark
                raise YamlLimitError(f"line {mark.line + 1}: nested more than {MAX_DEPTH} levels deep; a "
                                     f"configuration has sections of keys with plain values")
            return super().compose_node(parent, index)
        finally:
            self._depth -= 1

    def construct_object(self, node, deep=False):
        try:
            return super().construct_object(node, deep)
        except YamlLimitError:
            raise
        except (ValueError, TypeError, OverflowError) as exc:   # e.g. !!float 'x', a date that does not exist
            raise YamlLimitError(f"line {node.start_mark.line + 1}: a value cannot be read: {short(str(exc))}") from None

    def construct_mapping(self, node, deep=False):
        seen: dict = {}
        for key_node, _value in node.value:
            if not isinstance(key_node, yaml.ScalarNode) or key_node.tag == "tag:yaml.org,2002:merge":
                continue
            line = key_node.start_mark.line + 1
            if key_node.value in seen:
                raise YamlLimitError(f"duplicate key {short(key_node.value)} at lines {seen[key_node.value]} and "
                                     f"{line}: the second would silently replace the first; keep one")
            seen[key_node.value] = line
        return super().construct_mapping(node, deep)


_QUOTED_OR_COMMENT = re.compile(r"'[^'\n]*'|\"(?:[^\"\\\n]|\\.)*\"|#[^\n]*")


def flow_depth(bare: str) -> tuple[int, int]:
    """(depth, line): the deepest nesting of flow brackets ([ and {) in a text without its quotes and comments,
    and the line where it is first reached. PyYAML's scanner is quadratic in it (it keeps a possible key per
    level), so it is bounded before PyYAML sees it."""
    depth = deepest = 0
    where = 0
    for m in _BRACKETS.finditer(bare):
        depth = depth + 1 if m.group() in "[{" else max(0, depth - 1)
        if depth > deepest:
            deepest, where = depth, m.start()
    return deepest, bare.count("\n", 0, where) + 1


_BRACKETS = re.compile(r"[\[\]{}]")
_ALIAS = re.compile(r"(?:^|(?<=[\s\[{,:-]))\*[^\s,\[\]{}]+", re.M)


def load_yaml(text: str) -> Any:
    """The YAML document in ``text``, or YamlLimitError (one line, under 300 characters) saying what is wrong."""
    if len(text) > MAX_BYTES:
        raise YamlLimitError(f"{len(text)} bytes: larger than {MAX_BYTES} bytes, not a configuration")
    # quoted strings and comments are blanked, not removed, so that line numbers stay those of the text
    bare = _QUOTED_OR_COMMENT.sub(lambda m: re.sub(r"[^\n]", " ", m.group()), text)
    depth, line = flow_depth(bare)
    if depth > MAX_DEPTH:
        raise YamlLimitError(f"line {line}: brackets nested more than {MAX_DEPTH} levels deep; a configuration has "
                             f"sections of keys with plain values")
    aliases = list(_ALIAS.finditer(bare))
    if len(aliases) > MAX_ALIASES:
        line = bare.count("\n", 0, aliases[MAX_ALIASES].start()) + 1
        raise YamlLimitError(f"line {line}: more than {MAX_ALIASES} aliases (*name); write the values out")
    for n, line in enumerate(bare.splitlines(), 1):
        if not line.strip():   # blank, or only a comment or a quoted string (blanked above)
            continue
        lead = len(line) - len(line.lstrip(" \t-?:"))
        if lead > MAX_INDENT:
            raise YamlLimitError(f"line {n}: indented or nested more than {MAX_INDENT} characters deep; a "
                                 f"configuration has sections of keys with plain values")
    loader = None
    try:
        loader = _BoundedLoader(text)  # the reader checks the characters here already
        return loader.get_single_data()
    except YamlLimitError:
        raise
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        where = f"line {mark.line + 1} column {mark.column + 1}: " if mark else ""
        what = " ".join(str(x) for x in (exc.context, exc.problem) if x)
        raise YamlLimitError(f"not valid YAML: {where}{what[:200]}") from None
    except yaml.reader.ReaderError as exc:
        line = text.count("\n", 0, exc.position) + 1 if isinstance(exc.position, int) else "?"
        raise YamlLimitError(f"line {line}: not valid YAML: character {exc.character:#x}: {exc.reason}") from None
    except yaml.YAMLError as exc:
        raise YamlLimitError(f"not valid YAML: {str(exc).splitlines()[0][:200] if str(exc) else type(exc).__name__}") from None
    except (ValueError, TypeError, OverflowError) as exc:  # e.g. a date that does not exist
        raise YamlLimitError(f"a value cannot be read: {short(str(exc))}") from None
    except RecursionError:
        raise YamlLimitError(f"nested too deep (more than {MAX_DEPTH} levels)") from None
    finally:
        if loader is not None:
            loader.dispose()


def key_lines(text: str) -> dict[str, int]:
    """{"section": line, "section.key": line} of a configuration text's first two levels (1-based lines), for
    error messages; {} when the text does not parse (its own error names the line)."""
    lines: dict[str, int] = {}
    try:
        load_yaml(text)   # within the bounds first
        loader = _BoundedLoader(text)
        try:
            root = loader.get_single_node()
        finally:
            loader.dispose()
    except (YamlLimitError, yaml.YAMLError, ValueError, TypeError, RecursionError):
        return lines
    if not isinstance(root, yaml.MappingNode):
        return lines
    for sec, body in root.value:
        if not isinstance(sec, yaml.ScalarNode):
            continue
        lines.setdefault(sec.value, sec.start_mark.line + 1)
        if isinstance(body, yaml.MappingNode):
            for key, _value in body.value:
                if isinstance(key, yaml.ScalarNode):
                    lines.setdefault(f"{sec.value}.{key.value}", key.start_mark.line + 1)
    return lines
