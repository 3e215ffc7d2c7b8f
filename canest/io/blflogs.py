"""Binary logging format (``.blf``): read by python-can's reader as far as it goes, then say how far that was.

A BLF is a header and zlib-compressed blocks of frames. python-can's reader
stops silently where a cut file ends (the blocks' remains are dropped) and
raises on a corrupt block; both are reported here with the byte where the
frames end, and the bytes left unread are counted. A corrupt block ends the
reading: the blocks after it cannot be located reliably.
"""
from __future__ import annotations

import gzip
import zlib

import can

from canest.errors import CanestError, LogError


class BlockFeed:
    """A binary stream as the file object python-can's reader reads, counting bytes and noticing a short read."""

    def __init__(self, stream):
        self.stream = stream
        self.position = 0
        self.short = False  # a read got some but not all of what it asked for: the file ends inside an object

    def read(self, size: int = -1) -> bytes:
        try:
            data = self.stream.read(size)
        except (EOFError, zlib.error, gzip.BadGzipFile):  # a damaged .blf.gz: its data ends here
            self.short = True
            return b""
        self.position += len(data)
        if 0 < len(data) < size:
            self.short = True
        return data

    def close(self) -> None:
        self.stream.close()


def blf_frames(path, stream, size, damage):
    """The frames of a BLF of ``size`` bytes (None: compressed, unknown); a truncated or corrupt one ends with
    ``damage`` saying how far it was read (in bytes of the BLF itself)."""
    feed = BlockFeed(stream)
    try:
        reader = can.BLFReader(feed)
    except (CanestError, OSError):
        raise
    except Exception as exc:
        if feed.position == 0:
            return  # an empty file: no frames
        raise LogError(f"{path}: not a readable BLF file ({type(exc).__name__}: {exc}); is it a BLF log?") from None
    frames_end = feed.position
    try:
        for msg in reader:
            frames_end = feed.position
            yield msg
    except (CanestError, OSError):
        raise
    except Exception as exc:  # zlib.error, BLFParseError, struct.error: python-can cannot decode what follows
        end = feed.position if size is None else size
        cause = "truncated" if feed.short or feed.position >= end else "corrupt"
        damage.stop(cause, end - frames_end,
                    f"{cause}: frames read up to byte {frames_end} of {end}; the {end - frames_end} bytes after it "
                    f"could not be decoded ({type(exc).__name__}: {exc})")
        return
    remains = len(getattr(reader, "_tail", b""))  # python-can keeps an object cut by the end of the data there
    if feed.short or remains or (size is not None and reader.file_size > size):
        cut = f", {remains} bytes of a cut object were not" if remains else ""
        damage.stop("truncated", remains,
                    f"truncated: the file ends inside a block at byte {feed.position} (its header says "
                    f"{reader.file_size} bytes); the frames before the cut were read{cut}")
