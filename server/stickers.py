"""What a request may say about Woodward's unnamed stickers of one colour: their colour and
their head anchors, checked before any work (the live stereo socket's "start" and the
stereo tracking form alike). Refusals are `RetargetError`s (a `ValueError`) naming the field."""

from __future__ import annotations

import re

from retarget.errors import RetargetError
from retarget.sources.color_markers import MARKER_COLORS
from retarget.sources.stereo_live_stickers import MAX_STICKERS

__all__ = ["sticker_anchors", "sticker_color"]

_STICKER_NAME = re.compile(r"m(0[1-9]|[1-9][0-9])")


def sticker_color(color):
    """A colour as the library's `sticker_color` takes it: a name, "B,G,R" (as three
    numbers) or "hsv:H,S,V"."""
    if not isinstance(color, str) or len(color) > 40:
        raise RetargetError(f'"color" must be a colour name ({", ".join(MARKER_COLORS)}), "B,G,R" or '
                            f'"hsv:H,S,V"; got {color!r:.40}')
    text = color.strip().lower()
    if text in MARKER_COLORS:
        return text
    hsv = text.startswith("hsv:")
    parts = (text[4:] if hsv else text).split(",")
    try:
        values = [float(v) for v in parts]
    except ValueError:
        values = []
    if len(values) != 3:
        raise RetargetError(f'unknown sticker colour {color!r}: a name ({", ".join(MARKER_COLORS)}), "B,G,R" '
                            'or "hsv:H,S,V"')
    tops = (179, 255, 255) if hsv else (255, 255, 255)
    if not all(0 <= v <= top for v, top in zip(values, tops)):
        raise RetargetError(f"sticker colour {color!r}: " + (
            "hsv:H,S,V takes H 0-179, S and V 0-255 (OpenCV's 8-bit HSV)" if hsv else "B, G and R are 0-255"))
    return text if hsv else tuple(values)


def sticker_anchors(anchors) -> list[str] | None:
    """The stickers (columns m01..m99) that fix the head, >= 3 different ones, or None to
    choose them (the most mutually rigid)."""
    if anchors is None:
        return None
    if not (isinstance(anchors, list) and all(isinstance(a, str) for a in anchors)):
        raise RetargetError('"anchors" must be a list of sticker names (m01, m02, ...) or null to choose them')
    bad = [a for a in anchors if not _STICKER_NAME.fullmatch(a)]
    if bad:
        raise RetargetError(f'"anchors" are sticker columns m01..m{MAX_STICKERS}; {bad[0]!r:.40} is none')
    if len(set(anchors)) < 3 or len(anchors) > MAX_STICKERS:
        raise RetargetError(f'"anchors" must name at least 3 different stickers (the head frame needs 3); '
                            f"got {anchors!r:.80}")
    return anchors
