"""JPEG frames from the network (retarget.sources.jpeg_frames): the size from the header,
checked before the decoder sees the bytes."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from retarget.errors import RetargetError
from retarget.sources.jpeg_frames import decoded_jpeg, jpeg_size


def encoded(width: int, height: int, **params) -> bytes:
    image = np.random.default_rng(0).integers(0, 255, (height, width, 3), dtype=np.uint8)
    flags = [cv2.IMWRITE_JPEG_QUALITY, 80, cv2.IMWRITE_JPEG_PROGRESSIVE, int(params.get("progressive", False))]
    return cv2.imencode(".jpg", image, flags)[1].tobytes()


@pytest.mark.parametrize("progressive", [False, True])
def test_the_size_comes_from_the_header(progressive):
    assert jpeg_size(encoded(64, 48, progressive=progressive)) == (64, 48)


def test_broken_headers_are_refused_with_the_reason():
    good = encoded(64, 48)
    sof = good.index(b"\xff\xc0")
    for data, reason in ((b"GIF89a", "does not start with the SOI"), (good[:sof + 3], "ends before the frame header"),
                         (good[:sof + 9], "runs past the end"),
                         (good[:2] + b"\x00" * 8, "a marker was expected at byte 2"),
                         (good[:2] + b"\xff\xda\x00\x02" + good[2:], "no frame header"),
                         (good[:sof + 5] + b"\x00\x00" + good[sof + 7:], "the image is 64x0")):
        with pytest.raises(RetargetError, match=reason):
            jpeg_size(data)


def test_a_frame_of_another_size_is_refused_before_decoding():
    # the header says 65535 x 65535 (12 GiB decoded); the data behind it is never read
    huge = encoded(64, 48)
    sof = huge.index(b"\xff\xc0")
    huge = huge[:sof + 5] + b"\xff\xff\xff\xff" + huge[sof + 9:]
    with pytest.raises(RetargetError, match="the left image is 65535x65535; 64x48 was expected"):
        decoded_jpeg(huge, (64, 48), "left image")
    assert decoded_jpeg(encoded(64, 48), (64, 48)).shape == (48, 64, 3)
    with pytest.raises(RetargetError, match="not a JPEG the decoder can read"):
        decoded_jpeg(encoded(64, 48)[:300], (64, 48))
