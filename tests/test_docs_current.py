"""Docs, comments, help strings and tests describe the code as it is: no line of a tracked file refers to numbered
work periods, to sessions or rounds of work, to issue numbers, or to what the code did "previously".

A CAN session (app/can/session.py) and the MCU link's session (docs/firmware-protocol.md) are part of the product:
the patterns below name only the history forms (a number, or this/last/first... before the word)."""
import re
import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

HISTORY = re.compile("|".join([
    r"\bsessions? \d",                                   # a numbered work period, one or several
    r"\b(this|last|previous|earlier|first|second|third|next|that|later|work) sessions?\b",
    r"\bissues? #?\d",                                   # issue 12
    r"\b[a-z]+\d+ round\b(?! trip)", r"\brounds? \d", r"\b(this|last|previous|that|next) round\b",
    r"\bwork periods?\b", r"\blast time\b", r"\bpreviously\b",
    r"\b(before|after|until|since) (this|that|the last) (change|session|round|merge)\b",
    r"\bthe brief\b", r"\bbranch [a-z]+\d",
]), re.IGNORECASE)

# this file spells the patterns out; binary and generated model files hold no prose
SKIP_SUFFIXES = (".onnx", ".xml", ".jpg", ".png", ".mp4", ".npz", ".bin", ".dbc")


def tracked_files():
    out = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True, check=True).stdout
    for name in out.splitlines():
        path = ROOT / name
        if name == "tests/test_docs_current.py" or name.endswith(SKIP_SUFFIXES) or not path.is_file():
            continue
        yield name, path


def test_no_line_refers_to_the_history_of_the_work():
    hits = []
    for name, path in tracked_files():
        try:
            text = path.read_text()
        except UnicodeDecodeError:
            continue
        for number, line in enumerate(text.splitlines(), 1):
            m = HISTORY.search(line)
            if m:
                hits.append(f"{name}:{number}: {m.group(0)!r} in {line.strip()[:100]}")
    assert not hits, ("these lines refer to the history of the work; say what the code does now (history goes, "
                      "compressed, in docs/decisions.md):\n" + "\n".join(hits))


def test_the_patterns_catch_history_and_spare_the_can_session():
    for word in ("session", "sessions", "issue", "rounds"):
        assert HISTORY.search(f"measured (docs/PERFORMANCE.md, {word} 20-21)"), word
    assert HISTORY.search("Until this session the unit was the box width")
    assert HISTORY.search("Where issue 12 stands")
    assert HISTORY.search("#### The lanes10 round: one image")
    assert not HISTORY.search("session.publish(t, result, fcw=fcw)  # the CAN session")
    assert not HISTORY.search("the CAN session's own status; a float32 round trip")
    assert not HISTORY.search("HELLO (id 0x01), seq 0: host opens the session")
