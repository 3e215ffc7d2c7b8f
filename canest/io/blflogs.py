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
    """A binary stream as the file object python-can's reader reads, counting bytes and noticing a short read.

    Reads are capped at what the file holds (``size``; None: unknown), so a corrupt object length does not
    make python-can ask for gigabytes.
    """

    def __init__(self, stream, size=None):
        self.stream = stream
        self.size = size
        self.position = 0
        self.short = False  # a read got some but not all of what it asked for: the file ends inside an object
        self.hit_end = False  # a read got less than it asked for (also python-can probing past the last object)

    def read(self, size: int = -1) -> bytes:
        wanted = size
        if self.size is not None and (size < 0 or size > self.size - self.position):
            size = max(self.size - self.position, 0)
        try:
            data = self.stream.read(size)
        except (EOFError, zlib.error, gzip.BadGzipFile):  # a damaged .blf.gz: its data ends here
            self.short = self.hit_end = True
            return b""
        self.position += len(data)
        if wanted > len(data):
            self.hit_end = True
            self.short = self.short or len(data) > 0
        return data

    def close(self) -> None:
        self.stream.close()


def blf_frames(path, stream, size, damage):
    """The frames of a BLF of ``size`` bytes (None: compressed, unknown); a truncated or corrupt one ends with
    ``damage`` saying how far it was read (in bytes of the BLF itself)."""
    feed = BlockFeed(stream, size)
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
        cause = "truncated" if feed.hit_end else "corrupt"  # a read went past the end, or the data is wrong
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
