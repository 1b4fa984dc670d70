"""The one reader of recordings (a video file or a folder of images) for replay and evaluation.

A ``Recording`` gives gray frames with their media time (frame number / frame rate), the frame rate
(the video's own unless a valid ``fps`` is given; a folder needs one), the frame size, and an account
of what could not be used: ``expected`` (the container's frame count, or the folder's images),
``decoded``, and ``skipped`` (one line per frame or run of frames, with its name or number and why).

Frames are checked before they are used: an image file cut short (a JPEG without its end-of-image
marker, a PNG without IEND) is skipped, not decoded into a half-grey frame; a video that stops
decoding before the container's count says how many of its frames were lost.

``IMAGE_EXTS`` is the one list of still-image file names; the C++ image-folder source
(``is_image_file_name`` in csrc/capture) keeps its own copy, and a test checks that the two agree.
"""
from __future__ import annotations

import math
import re
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator, Optional, Union

import cv2
import numpy as np

from app.decode_errors import FfmpegErrors, jpeg_warnings

IMAGE_EXTS = (".png", ".jpg", ".jpeg", ".bmp", ".pgm", ".ppm", ".tif", ".tiff", ".webp")
# Frame rates a recording may be played at (frames/s): a tenth of a frame per second (time-lapse) up to
# 1000 (high-speed cameras); also the range of the configuration's source.fps.
FPS_MIN, FPS_MAX = 0.1, 1000.0
# A video whose reads fail this many times in a row has ended (a truncated file fails on every read
# from the cut on); fewer failures are corrupt frames, skipped.
MAX_FAILED_READS = 5
# JPEG end-of-image marker must be within this many bytes of the end (cameras pad with a few bytes;
# an EXIF thumbnail's own marker sits near the start).
JPEG_TAIL_BYTES = 1024


class RecordingError(ValueError):
    """A recording that cannot be played; the message names it and says how to fix it."""


def is_image_file(path: Union[str, Path]) -> bool:
    return Path(path).suffix.lower() in IMAGE_EXTS


def natural_key(name: str) -> tuple:
    """Sort key of a file name in natural order: runs of digits compare as numbers, so 2.jpg comes before 10.jpg
    (TuSimple's clips are 1.jpg .. 20.jpg); names equal as numbers (01.jpg, 1.jpg) fall back to plain order. The
    C++ image-folder source sorts the same way (natural_name_less in csrc/capture)."""
    parts = re.split(r"(\d+)", name)  # text, digits, text, ...: a number always meets a number
    return tuple(int(x) if i % 2 else x for i, x in enumerate(parts)), name


def folder_images(folder: Union[str, Path]) -> list[Path]:
    """The image files of a folder in natural order (natural_key: the order they are played in)."""
    return sorted((x for x in Path(folder).iterdir() if x.is_file() and is_image_file(x)),
                  key=lambda x: natural_key(x.name))


def check_fps(fps: float, what: str = "--fps") -> float:
    """``fps`` as a float, or RecordingError if it is not a frame rate in [FPS_MIN, FPS_MAX]."""
    try:
        value = float(fps)
    except (TypeError, ValueError):
        raise RecordingError(f"{what} {fps!r}: not a number; give frames per second between {FPS_MIN:g} and "
                             f"{FPS_MAX:g}") from None
    if not (math.isfinite(value) and FPS_MIN <= value <= FPS_MAX):
        raise RecordingError(f"{what} {fps}: must be a frame rate between {FPS_MIN:g} and {FPS_MAX:g} frames/s")
    return value


def truncation(data: bytes, suffix: str) -> Optional[str]:
    """Why an image file's bytes are cut short, or None if they look whole (JPEG and PNG are checked;
    the other formats are left to the decoder)."""
    suffix = suffix.lower()
    if suffix in (".jpg", ".jpeg"):
        if not data.startswith(b"\xff\xd8"):
            return "not a JPEG (no start-of-image marker)"
        if data.rfind(b"\xff\xd9", max(0, len(data) - JPEG_TAIL_BYTES)) < 0:
            return "truncated JPEG (no end-of-image marker)"
    elif suffix == ".png":
        if not data.startswith(b"\x89PNG"):
            return "not a PNG (no signature)"
        if data.rfind(b"IEND", max(0, len(data) - 32)) < 0:
            return "truncated PNG (no IEND chunk)"
    return None


def read_image(path: Union[str, Path], flags: int = cv2.IMREAD_GRAYSCALE) -> tuple[Optional[np.ndarray], str]:
    """(image, "") or (None, why): an image file decoded only if it is whole."""
    p = Path(path)
    try:
        data = p.read_bytes()
    except OSError as exc:
        return None, f"cannot be read ({exc.strerror or exc})"
    if not data:
        return None, "empty file"
    why = truncation(data, p.suffix)
    if why:
        return None, why
    if p.suffix.lower() in (".jpg", ".jpeg"):   # libjpeg decodes corrupt data into grey blocks, with a warning
        img, warned = jpeg_warnings(data, flags)
        if warned and img is not None:
            return None, f"corrupt JPEG data (libjpeg: {warned})"
    else:
        img = cv2.imdecode(np.frombuffer(data, np.uint8), flags)
    if img is None:
        return None, "cannot be decoded as an image"
    return img, ""


@dataclass
class Recording:
    path: Path
    kind: str                      # "video" or "folder"
    fps: float                     # frames/s of the media time
    size: tuple[int, int]          # (width, height) of the first frame; others of another size are skipped
    expected: Optional[int]        # the container's frame count, or the folder's images; None if unknown
    decoded: int = 0               # frames delivered so far
    skipped: list[str] = field(default_factory=list)   # "name or number: why", one per frame or run
    damaged: list[int] = field(default_factory=list)   # video frames the decoder logged errors for (concealed)
    decode_errors: Counter = field(default_factory=Counter)   # FFmpeg's error messages by reason
    _names: list[Path] = field(default_factory=list, repr=False)

    def frames(self) -> Iterator[tuple[int, float, np.ndarray]]:
        """(frame number, media time s, gray image) for every usable frame, in order."""
        return ((i, t, gray) for i, t, gray, _bgr in self.colour_frames(False))

    def colour_frames(self, colour: bool = True) -> Iterator[tuple[int, float, np.ndarray, Optional[np.ndarray]]]:
        """(frame number, media time s, gray image, BGR image) for every usable frame, in order: the gray image
        exactly as frames() gives it (what the core sees), the BGR one for drawing (None unless `colour`)."""
        return self._folder_frames(colour) if self.kind == "folder" else self._video_frames(colour)

    def read_all(self, max_frames: Optional[int] = None) -> list[np.ndarray]:
        out = []
        for _i, _t, gray in self.frames():
            if max_frames is not None and len(out) >= max_frames:
                break
            out.append(gray)
        return out

    def _usable(self, label: str, img: np.ndarray) -> bool:
        if (img.shape[1], img.shape[0]) != self.size:
            self.skipped.append(f"{label}: {img.shape[1]}x{img.shape[0]}, the recording's first frame is "
                                f"{self.size[0]}x{self.size[1]}")
            return False
        self.decoded += 1
        return True

    def _folder_frames(self, colour: bool):
        for i, name in enumerate(self._names):
            img, why = read_image(name)
            if img is None:
                self.skipped.append(f"{name.name}: {why}")
            elif self._usable(name.name, img):
                yield i, i / self.fps, img, read_image(name, cv2.IMREAD_COLOR)[0] if colour else None

    def _video_frames(self, colour: bool):
        # one decoding thread: FFmpeg's messages then belong to the frame being read, the same on every run
        cap = cv2.VideoCapture(str(self.path), cv2.CAP_FFMPEG, [cv2.CAP_PROP_N_THREADS, 1])
        errors = FfmpegErrors.watch()   # FFmpeg conceals a damaged frame; its log says so
        i, failed = 0, 0  # frame number of the next read; failed reads in a row before it
        try:
            while True:
                mark = errors.mark() if errors else None
                ok, bgr = cap.read()
                new = errors.since(mark) if errors else None
                if new:
                    self.damaged.append(i)
                    self.decode_errors.update(new)
                if not ok or bgr is None:
                    if self.expected is None or i >= self.expected:
                        break  # the end the container announced
                    failed += 1
                    i += 1
                    if failed >= MAX_FAILED_READS:
                        break
                    continue
                if failed:
                    self.skipped.append(_frame_run(i - failed, i - 1, "cannot be decoded (corrupt)"))
                    failed = 0
                gray = bgr if bgr.ndim == 2 else cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY)
                if self._usable(f"frame {i}", gray):
                    yield i, i / self.fps, gray, bgr if colour and bgr.ndim == 3 else None
                i += 1
        finally:
            cap.release()
        first_lost = i - failed
        if self.expected is not None and first_lost < self.expected:
            self.skipped.append(_frame_run(first_lost, self.expected - 1, "not decoded: the file is truncated or "
                                           f"corrupt ({self.decoded} of {self.expected} frames decoded)"))

    def account(self) -> str:
        """'N of M frames decoded' (M the container's count or the folder's images)."""
        of = f" of {self.expected}" if self.expected is not None else ""
        if not self.damaged:
            return f"{self.decoded}{of} frames decoded"
        reasons = ", ".join(f"{why} {n}" for why, n in self.decode_errors.most_common(3))
        return (f"{self.decoded}{of} frames decoded, {len(self.damaged)} of them with decoder errors, concealed by "
                f"FFmpeg: {_frame_list(self.damaged)}; the frames after a damaged one may be spoilt up to the next "
                f"key frame ({reasons})")


def _frame_list(frames: list[int]) -> str:
    """"frames 3, 9, 17" (the first 8 and how many more)."""
    shown = ", ".join(str(f) for f in frames[:8])
    return f"frame{'s' if len(frames) > 1 else ''} {shown}" + (f" and {len(frames) - 8} more" if len(frames) > 8 else "")


def _frame_run(first: int, last: int, why: str) -> str:
    return f"frame {first}: {why}" if first == last else f"frames {first}-{last}: {why}"


def open_recording(source: Union[str, Path], fps: Optional[float] = None) -> Recording:
    """A video file or an image folder, checked: RecordingError says what is wrong and what to do."""
    p = Path(source)
    if fps is not None:
        fps = check_fps(fps)
    if p.is_dir():
        if fps is None:
            raise RecordingError(f"{source}: an image folder needs its frame rate: give --fps N")
        names = folder_images(p)
        if not names:
            raise RecordingError(f"{source}: the folder contains no images ({' '.join(IMAGE_EXTS)})")
        first, why = None, ""
        for name in names:  # the first whole image sets the size
            first, why = read_image(name)
            if first is not None:
                break
        if first is None:
            raise RecordingError(f"{source}: none of its {len(names)} images can be decoded ({names[0].name}: {why})")
        return Recording(p, "folder", fps, (first.shape[1], first.shape[0]), len(names), _names=names)
    if not p.exists():
        raise RecordingError(f"{source}: no such file or folder")
    if is_image_file(p):
        raise RecordingError(f"{source}: is a still image; replay a folder of images (with --fps) or use "
                             f"`headway detect`")
    cap = cv2.VideoCapture(str(p), cv2.CAP_FFMPEG)
    FfmpegErrors.watch()   # from OpenCV's first open on, FFmpeg's errors are counted, not printed
    try:
        ok, frame = cap.read() if cap.isOpened() else (False, None)
        if not ok:
            raise RecordingError(f"{source}: cannot be read as a video (not a video file, or empty/corrupt)")
        own = cap.get(cv2.CAP_PROP_FPS)
        count = int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
    finally:
        cap.release()
    if fps is None:
        if not (math.isfinite(own) and FPS_MIN <= own <= FPS_MAX):
            raise RecordingError(f"{source}: the video gives no usable frame rate ({own:g}): give --fps N")
        fps = float(own)
    return Recording(p, "video", fps, (frame.shape[1], frame.shape[0]), count if count > 0 else None)
