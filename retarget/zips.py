"""Zip archives read within bounds: what a zip claims is checked before anything is
unpacked, and every read is bounded whatever the headers say.

A zip can claim anything in its central directory and unpack to far more than its own
size. `opened_zip` counts the directory's entries before zipfile makes an object for
each; `check_members` refuses, from the directory alone, members that are encrypted,
compressed by a method zipfile does not bound (bzip2, LZMA: only stored and Deflate are
read), larger than a member may be, packed more tightly than `MAX_COMPRESSION_RATIO`, or
more than the archive may unpack to in all; `unpacked` reads a member through to its
CRC check, no further than its declared size or the budget left.
"""

from __future__ import annotations

import io
import zipfile
import zlib

from retarget.errors import RetargetError

__all__ = ["MAX_ARCHIVE_MEMBERS", "MAX_COMPRESSION_RATIO", "ZIP_ERRORS", "check_members",
           "opened_zip", "unpacked", "zip_problem"]

MAX_ARCHIVE_MEMBERS = 100_000
"""Most entries a zip's central directory may hold (zipfile makes an object for each)."""

MAX_COMPRESSION_RATIO = 100
"""Most a member over 4 KiB may claim to unpack to per packed byte: text deflates 3-5:1
(10:1 for coarse coordinates), images hardly at all, while a zip bomb's members claim
~1000:1."""

_RATIO_FLOOR = 4096  # tiny members may pack better than MAX_COMPRESSION_RATIO
_METHODS = {zipfile.ZIP_STORED: "stored", zipfile.ZIP_DEFLATED: "Deflate"}
_METHOD_NAMES = {zipfile.ZIP_BZIP2: "bzip2", zipfile.ZIP_LZMA: "LZMA", 9: "Deflate64",
                 93: "Zstandard", 99: "AES encryption"}
ZIP_ERRORS = (zipfile.BadZipFile, zipfile.LargeZipFile, zlib.error, EOFError, OSError, ValueError,
              NotImplementedError, UnicodeError)
"""What zipfile raises on a damaged archive."""


def opened_zip(data: bytes, label: str) -> zipfile.ZipFile:
    """The archive in `data`, its entry count checked first."""
    entries = data.count(b"PK\x01\x02")  # central directory entries, at most
    if entries > MAX_ARCHIVE_MEMBERS:
        raise RetargetError(
            f"{label} holds {entries} zip entries; at most {MAX_ARCHIVE_MEMBERS} are read")
    try:
        return zipfile.ZipFile(io.BytesIO(data))
    except ZIP_ERRORS as exc:
        raise RetargetError(f"{label} is not a zip archive: {exc}") from None


def check_members(infos, label: str, max_bytes: int, max_member_bytes: int, *,
                  things: str = "files", thing: str = "file", content: str = "such files",
                  total: str = "", advice: str = "") -> None:
    """Refuse, from the central directory alone, members that cannot be read or that claim
    too much (module docstring); `things`/`thing` name the members in messages, `content`
    what they hold (a compression ratio's message); a total over `max_bytes` is refused
    naming them as `total` (default `things`), with `advice` at the end."""
    for info in infos:
        where = f"{label}: {info.filename!r}"
        if info.flag_bits & 0x1:
            raise RetargetError(f"{where} is encrypted; zip the {things} without a password")
        if info.compress_type not in _METHODS:
            method = _METHOD_NAMES.get(info.compress_type, "an unknown method")
            raise RetargetError(
                f"{where} is compressed with {method} (zip method {info.compress_type}), which is "
                f"not read; zip the {things} with Deflate (the usual zip compression)")
        if info.file_size > max_member_bytes:
            raise RetargetError(
                f"{where} unpacks to {info.file_size} bytes; a {thing} may have at most "
                f"{max_member_bytes}")
        if info.file_size > _RATIO_FLOOR \
                and info.file_size > MAX_COMPRESSION_RATIO * max(info.compress_size, 1):
            raise RetargetError(
                f"{where} claims to unpack {info.compress_size} bytes to {info.file_size} "
                f"({info.file_size / max(info.compress_size, 1):.0f}:1); {content} packs at most "
                f"{MAX_COMPRESSION_RATIO}:1, so the archive is damaged or a zip bomb")
    size = sum(info.file_size for info in infos)
    if size > max_bytes:
        raise RetargetError(
            f"{label}: its {len(infos)} {total or things} unpack to {size} bytes; at most "
            f"{max_bytes} are read{advice}")


def unpacked(archive: zipfile.ZipFile, info: zipfile.ZipInfo, label: str, budget: list) -> bytes:
    """The member's bytes, the read bounded by its declared size and ``budget[0]``, the
    bytes still to unpack (decreased by what is read)."""
    where = f"{label}: {info.filename!r}"
    try:
        with archive.open(info) as handle:
            raw = handle.read(min(info.file_size, budget[0]) + 1)
            if len(raw) <= info.file_size:
                handle.read(1)  # reach the end, where zipfile checks the CRC
    except ZIP_ERRORS as exc:
        raise RetargetError(f"{where} could not be unpacked: {zip_problem(exc)}") from None
    budget[0] -= len(raw)
    if budget[0] < 0 or len(raw) > info.file_size:
        raise RetargetError(f"{where} unpacks to more than its declared {info.file_size} bytes")
    return raw


def zip_problem(exc: Exception) -> str:
    """What a zipfile error says about the archive, in words."""
    if isinstance(exc, zipfile.BadZipFile) and "CRC" in str(exc):
        return f"its data does not match its checksum ({exc})"
    return f"{type(exc).__name__}: {exc}"
