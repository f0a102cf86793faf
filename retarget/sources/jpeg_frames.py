"""JPEG frames from the network: the size read from the header, then the decode.

A live source receives JPEGs from the network; their size decides how much memory the
decoder will take, so it is read from the header (ITU T.81, B.2) and checked in Python
before the native decoder (OpenCV's libjpeg) sees the bytes. The decode itself should
still run where a crash costs nothing (the server runs it in a child process).
"""

from __future__ import annotations

import struct

import cv2
import numpy as np

from retarget.errors import RetargetError

__all__ = ["jpeg_size", "decoded_jpeg"]

# Start-of-frame markers (baseline, extended, progressive, lossless; Huffman or arithmetic)
# carry the frame's size; C4 (DHT), C8 (JPG) and CC (DAC) share the range but do not.
_SOF = frozenset(range(0xC0, 0xD0)) - {0xC4, 0xC8, 0xCC}
# Markers with no length field: TEM, RST0-7 (SOI and EOI end the walk or are refused).
_STANDALONE = frozenset({0x01, *range(0xD0, 0xD8)})


def jpeg_size(data: bytes) -> tuple[int, int]:
    """(width, height) px of a JPEG from its start-of-frame segment.

    data : the file's bytes. `RetargetError` naming the problem when it does not start
    as a JPEG, its segments run past its end, or no frame header precedes the scan.
    """
    view = memoryview(data)
    if len(view) < 4 or view[0] != 0xFF or view[1] != 0xD8:
        raise RetargetError("not a JPEG: it does not start with the SOI marker FF D8")
    at = 2
    while at + 4 <= len(view):
        if view[at] != 0xFF:
            raise RetargetError(f"JPEG header: a marker was expected at byte {at}")
        marker = view[at + 1]
        if marker == 0xFF:  # fill byte before a marker
            at += 1
            continue
        if marker in _STANDALONE:
            at += 2
            continue
        if marker in (0xD8, 0xD9, 0xDA):
            break  # a second SOI, the end, or the scan: no frame header came first
        (length,) = struct.unpack_from(">H", view, at + 2)
        if length < 2 or at + 2 + length > len(view):
            raise RetargetError(f"JPEG header: a segment at byte {at} runs past the end of the data")
        if marker in _SOF:
            if length < 8:
                raise RetargetError("JPEG header: the frame header is too short")
            height, width = struct.unpack_from(">HH", view, at + 5)
            if width == 0 or height == 0:
                raise RetargetError(f"JPEG header: the image is {width}x{height}")
            return int(width), int(height)
        at += 2 + length
    else:
        raise RetargetError("JPEG header: the data ends before the frame header (SOF)")
    raise RetargetError("JPEG header: no frame header (SOF) before the image data")


def decoded_jpeg(data: bytes, size: tuple[int, int], what: str = "image") -> np.ndarray:
    """(H, W, 3) uint8 BGR image of a JPEG that must be `size` (width, height) px.

    The header's size is checked before decoding; `RetargetError` naming `what` for a
    JPEG of another size or one the decoder cannot read.
    """
    try:
        width, height = jpeg_size(data)
    except RetargetError as exc:
        raise RetargetError(f"the {what}: {exc}") from None
    if (width, height) != tuple(size):
        raise RetargetError(f"the {what} is {width}x{height}; {size[0]}x{size[1]} was expected")
    image = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
    if image is None or image.shape != (height, width, 3):
        raise RetargetError(f"the {what} is not a JPEG the decoder can read")
    return image
