"""Output files that never destroy an input and are never seen half-written.

``check_outputs`` refuses, before anything is opened, an output path that is one of the command's inputs
(the same path, a hard or symbolic link to it, or the same file under another name) or another output:
opening it for writing would truncate the input first. ``written_whole`` gives the writer a temporary
file beside the output (same folder, so the rename stays on one file system; same suffixes, so writers that
choose the format by them, OpenCV's, python-can's and NumPy's, choose the right one) and renames it into
place only when the work completed; a run that fails leaves the previous output as it was and no partial
file. ``write_whole`` does that for a text written at once, ``folder_written_whole`` for a folder of files
(frames, example images) that is one output.
"""
from __future__ import annotations

import contextlib
import os
import shutil
from pathlib import Path
from typing import Iterable, Iterator, Mapping, Optional

from app.safe_yaml import short_path


class OutputPathError(ValueError):
    """An output path that would overwrite an input or another output; the message names both."""


def _same(a: Path, b: Path) -> bool:
    try:
        if a.exists() and b.exists():
            return os.path.samefile(a, b)
    except (OSError, ValueError):
        pass
    return os.path.realpath(a) == os.path.realpath(b)


def check_outputs(outputs: Mapping[str, Optional[str]], inputs: Mapping[str, Optional[str]]) -> None:
    """OutputPathError if an output (``{"--tracks": path}``; None = not written) names an input (same shape)
    or another output."""
    given_in = [(name, Path(p)) for name, p in inputs.items() if p]
    seen: list[tuple[str, Path]] = []
    for name, path in outputs.items():
        if not path:
            continue
        out = Path(path)
        for other, p in given_in + seen:
            if _same(out, p):
                kind = "an output" if (other, p) in seen else "an input"
                raise OutputPathError(f"{name} {short_path(path)}: is {other} ({short_path(p)}), {kind} of "
                                      f"this run; writing it would destroy it: give another path")
        seen.append((name, out))


def numbered(name: str, paths: Iterable[Optional[str]]) -> dict[str, Optional[str]]:
    """Several inputs of one kind in ``check_outputs``' form, named by their place: {"input 1": path, ...}."""
    return {f"{name} {i + 1}": p for i, p in enumerate(paths)}


def folder_outputs(option: str, folder: Optional[str], names: Iterable[str]) -> dict[str, Optional[str]]:
    """An output folder and the files a command writes into it, in ``check_outputs``' form: the folder must
    not be an input, nor may any of those files (an input kept where the command writes)."""
    if not folder:
        return {}
    return {option: folder, **{f"{option}'s {name}": str(Path(folder) / name) for name in names}}


def partial_path(path: str) -> Path:
    """The temporary file an output is written to before it is renamed into place: hidden, the writing
    process in its name, every suffix kept (``x.yml.gz`` -> ``.x.partial-PID.yml.gz``)."""
    p = Path(path)
    suffixes = "".join(p.suffixes)
    base = p.name[:len(p.name) - len(suffixes)] if suffixes else p.name
    return p.with_name(f".{base}.partial-{os.getpid()}{suffixes}")


@contextlib.contextmanager
def written_whole(path: Optional[str]) -> Iterator[Optional[str]]:
    """The path to write ``path``'s content to; renamed to ``path`` when the block ends without an error,
    removed when it raises. None passes through (no output)."""
    if not path:
        yield None
        return
    tmp = partial_path(path)
    try:
        yield str(tmp)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    if tmp.exists():
        os.replace(tmp, path)


def write_whole(path: str | Path, text: str) -> None:
    """``text`` into ``path``, which changes only once the whole text is written."""
    with written_whole(str(path)) as tmp:
        Path(tmp).write_text(text)


@contextlib.contextmanager
def folder_written_whole(path: str | Path) -> Iterator[str]:
    """A new empty folder to fill in place of the folder ``path``: it replaces ``path`` (and all that was in
    it) when the block ends without an error, and is removed when it raises."""
    final = Path(path)
    tmp = partial_path(str(final))
    shutil.rmtree(tmp, ignore_errors=True)   # left by a process of the same id that was killed
    tmp.mkdir(parents=True)
    try:
        yield str(tmp)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    # a folder cannot be renamed over one that holds files: the old one is moved aside, then removed
    old = final.with_name(f".{final.name}.old-{os.getpid()}")
    if final.exists():
        os.replace(final, old)
    os.replace(tmp, final)
    shutil.rmtree(old, ignore_errors=True)
