"""Decoder errors that would otherwise pass unseen: FFmpeg's, while it conceals a damaged video frame, and
libjpeg's warnings on a corrupt JPEG. Both decoders still hand back an image, so a reader that only checks
for an image plays damaged frames as if whole.

FFmpeg: every message of level error or worse that FFmpeg logs is counted, by its text with the numbers
left out ("error while decoding MB", "concealing DC, AC, MV errors in P frame", ...), through FFmpeg's own
log callback (``av_log_set_callback``) in the libavutil that OpenCV's cv2 loaded; a frame during whose
decoding one is logged is a damaged frame. The callback is set after OpenCV's first video open, because
OpenCV sets its own then. A damaged reference frame also spoils the frames that follow it up to the next
key frame without new messages; the count is of the frames the decoder itself reported.

libjpeg: its warnings go to the process's stderr (file descriptor 2); ``jpeg_warnings`` decodes with that
descriptor pointed at a temporary file and returns what was written there.
"""
from __future__ import annotations

import ctypes
import os
import re
import tempfile
import threading
from collections import Counter
from pathlib import Path
from typing import Optional

import cv2
import numpy as np

AV_LOG_ERROR = 16  # FFmpeg's log levels: lower is more severe (panic 0, fatal 8, error 16, warning 24)
_NUMBERS = re.compile(r"%[-+ #0-9.]*[a-zA-Z]+|\s+")
_LOG_FN = ctypes.CFUNCTYPE(None, ctypes.c_void_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_void_p)


def reason(fmt: bytes) -> str:
    """FFmpeg's message template without its numbers, as the reason a frame is counted under."""
    text = _NUMBERS.sub(" ", fmt.decode("ascii", "replace"))
    text = re.sub(r"\s+([,.:;])", r"\1", re.sub(r"\s+", " ", text)).strip(" ,.:")
    return text[:60] or "decoder error"


class FfmpegErrors:
    """Counts FFmpeg's error messages (process-wide: FFmpeg has one log) by reason."""

    _instance: Optional["FfmpegErrors"] = None
    _lock = threading.Lock()

    def __init__(self, libavutil: ctypes.CDLL):
        self.total = 0
        self.reasons: Counter = Counter()
        self._callback = _LOG_FN(self._on_log)   # kept: FFmpeg holds only the pointer
        self._lib = libavutil

    def _on_log(self, _avcl, level, fmt, _args) -> None:
        if level <= AV_LOG_ERROR and fmt:
            self.reasons[reason(fmt)] += 1
            self.total += 1

    def since(self, mark: tuple[int, Counter]) -> Counter:
        """The reasons logged since ``mark()`` was taken."""
        return self.reasons - mark[1] if self.total != mark[0] else Counter()

    def mark(self) -> tuple[int, Counter]:
        return self.total, Counter(self.reasons) if self.total else Counter()

    @classmethod
    def watch(cls) -> Optional["FfmpegErrors"]:
        """The process's counter, its callback set again: call it after each cv2.VideoCapture open (OpenCV
        sets its own callback there when OPENCV_FFMPEG_LOGLEVEL is set). None where cv2's FFmpeg cannot be
        found (then nothing is counted)."""
        with cls._lock:
            if cls._instance is None:
                lib = _cv2_libavutil()
                if lib is not None:
                    cls._instance = cls(lib)
            if cls._instance is not None:
                cls._instance._lib.av_log_set_callback(cls._instance._callback)
            return cls._instance


def _cv2_libavutil() -> Optional[ctypes.CDLL]:
    """The libavutil that cv2's FFmpeg uses: the wheel's own copy beside it, else the system's."""
    here = Path(cv2.__file__).resolve().parent
    candidates = sorted(here.parent.glob("opencv_python*.libs/libavutil*.so*")) + sorted(here.glob("**/libavutil*.so*"))
    for path in candidates + ["libavutil.so.60", "libavutil.so.59", "libavutil.so.58", "libavutil.so.57"]:
        try:
            return ctypes.CDLL(str(path), mode=getattr(os, "RTLD_NOLOAD", 0) | os.RTLD_NOW)
        except OSError:
            continue
    return None


_stderr_lock = threading.Lock()


def jpeg_warnings(data: bytes, flags: int = cv2.IMREAD_GRAYSCALE) -> tuple[Optional[np.ndarray], str]:
    """(image or None, libjpeg's warnings in one line, "" if none) for the bytes of a JPEG file."""
    with _stderr_lock, tempfile.TemporaryFile() as capture:
        saved = os.dup(2)
        try:
            os.dup2(capture.fileno(), 2)
            img = cv2.imdecode(np.frombuffer(data, np.uint8), flags)
        finally:
            os.dup2(saved, 2)
            os.close(saved)
        capture.seek(0)
        text = capture.read(4096).decode("utf-8", "replace")
    said = [line.strip() for line in text.splitlines() if line.strip()]
    return img, "; ".join(dict.fromkeys(said))[:160]
