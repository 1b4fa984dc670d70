"""Fuzzing the configuration loader: 10,000 random mutations of the default configuration (characters
inserted and deleted, lines duplicated and swapped, odd values, anchors and aliases, deep nesting,
truncation), with a fixed seed. Each ends as a loaded configuration or as one error line under 500
characters, never an exception of another kind, and the loader's memory stays under 100 MB."""
from __future__ import annotations

import random
import resource

import yaml

from app import config as configuration
from app.config import ConfigFileError

CASES = 10_000
SEED = 14
SPECIAL = list(":-&*[]{}!#'\"\t %?|>@`,\\\n") + ["\u00e9", "\u202e", "\x00", "\ufeff"]
VALUES = ["nan", ".inf", "-.inf", "-1e999", "1e999", "~", "yes", "no", "0x1F", "0o17", "2020-13-45", "[1, 2]",
          "{a: 1}", "''", "!!binary aGk=", "!!python/object:os.system", "&x 3", "*x", "*nope", "? [a]", "- x",
          "'" + "w" * 5000 + "'", "12345678901234567890123", "!!float 'x'", "<<: {a: 1}"]


def sections(rng: random.Random, dumped: dict[str, list[str]]) -> list[str]:
    """1-3 sections of the default configuration as block YAML lines (``dumped``: each section's lines)."""
    return [line for s in rng.sample(sorted(dumped), rng.randint(1, 3)) for line in dumped[s]]


def mutate(rng: random.Random, lines: list[str]) -> str:
    for _ in range(rng.randint(1, 4)):
        op = rng.randrange(10)
        i = rng.randrange(len(lines)) if lines else 0
        if not lines:
            lines = ["camera:"]
            continue
        line = lines[i]
        if op == 0 and line:                                   # delete a character
            j = rng.randrange(len(line))
            lines[i] = line[:j] + line[j + 1:]
        elif op == 1:                                          # insert a YAML-special character
            j = rng.randrange(len(line) + 1)
            lines[i] = line[:j] + rng.choice(SPECIAL) + line[j:]
        elif op == 2:                                          # duplicate a line: duplicate keys
            lines.insert(rng.randrange(len(lines) + 1), line)
        elif op == 3:                                          # swap two lines
            k = rng.randrange(len(lines))
            lines[i], lines[k] = lines[k], line
        elif op == 4 and ":" in line:                          # an odd value
            lines[i] = line.split(":", 1)[0] + ": " + rng.choice(VALUES)
        elif op == 5:                                          # an alias bomb of random depth
            n = rng.randint(2, 12)
            bomb = [f"  k0: &a0 [x, x, x, x, x, x, x, x, x]"]
            bomb += [f"  k{j}: &a{j} [" + ", ".join([f"*a{j - 1}"] * 9) + "]" for j in range(1, n)]
            lines[i + 1:i + 1] = bomb
        elif op == 6:                                          # deep nesting
            n = rng.choice([5, 19, 25, 200, 5000])
            opener, closer = rng.choice([("[", "]"), ("{a: ", "}")])
            lines.insert(i, "  deep: " + opener * n + "1" + closer * n)
        elif op == 7:                                          # re-indent a line
            lines[i] = " " * rng.choice([0, 1, 3, 4, 8]) + line.lstrip()
        elif op == 8:                                          # a section twice, or a whole new one
            lines += rng.choice([lines[:3], ["camera:", "  fx: 1", "camera: {}"], ["x" * 300 + ":", "  y: 1"]])
        else:                                                  # truncate anywhere
            text = "\n".join(lines)
            return text[:rng.randrange(len(text) + 1)]
    return "\n".join(lines) + "\n"


def test_random_mutations_load_or_give_one_short_line_in_bounded_memory():
    rng = random.Random(SEED)
    dumped = {s: yaml.safe_dump({s: v}, sort_keys=False).splitlines() for s, v in configuration.defaults().items()}
    before_kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    loaded = errors = 0
    for case in range(CASES):
        text = mutate(rng, sections(rng, dumped))
        try:
            cfg = configuration.validate(configuration.parse(text, "fuzz.yaml"), "fuzz.yaml")
        except ConfigFileError as exc:
            msg = str(exc)
            assert "\n" not in msg and len(msg) < 500 and msg.startswith("fuzz.yaml: "), (case, text[:300], msg[:600])
            errors += 1
        else:
            assert set(cfg) == set(configuration.schema()), case
            loaded += 1
    grown_mb = (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before_kb) / 1024
    assert grown_mb < 100, f"the loader's peak memory grew by {grown_mb:.0f} MB"
    # the mutations are neither all harmless nor all fatal: both outcomes are exercised
    assert loaded > CASES // 20 and errors > CASES // 4, (loaded, errors)
