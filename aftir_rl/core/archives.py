"""Zip archives from untrusted files, read under limits on what they really hold.

A zip's directory declares each entry's size, but only inflating an entry tells what it holds.
:class:`BoundedZip` reads an archive held in memory entry by entry, :data:`CHUNK_BYTES` at a
time, counting the bytes actually produced against a budget, and stops at the budget whatever
the directory declares. Its directory is parsed only when it is at most
:data:`MAX_DIRECTORY_BYTES` long, and only stored or deflated entries are read (deflate needs
32 kB of state). Reading an archive thus costs its own bytes (copied once when given as a
``bytearray``) and at most the budget besides. Every failure is a one-line
:class:`~aftir_rl.core.errors.CheckpointError`.
"""

from __future__ import annotations

import io
import zipfile
import zlib
from collections.abc import Callable
from types import TracebackType

from aftir_rl.core.config import brief, shorten
from aftir_rl.core.errors import CheckpointError

__all__ = ["CHUNK_BYTES", "MAX_DIRECTORY_BYTES", "METHODS", "BoundedZip"]

#: Bytes inflated at a time (zipfile's ``read()`` of a whole entry inflates up to 2 GB at once).
CHUNK_BYTES = 1 << 20

#: The longest central directory parsed [bytes]: zipfile builds an object of about 500 bytes
#: for each of its entries (46 bytes and up), so a directory of 50 MB would cost gigabytes.
MAX_DIRECTORY_BYTES = 1 << 20

#: The compression methods read: stored and deflated (bzip2 and LZMA need more state).
METHODS = (zipfile.ZIP_STORED, zipfile.ZIP_DEFLATED)

#: What zipfile and zlib raise on a damaged archive.
_ZIP_ERRORS = (zipfile.BadZipFile, zlib.error, OSError, EOFError, ValueError, RuntimeError)


class _Capped(io.BytesIO):
    """Bytes read through zipfile, refusing any read longer than the longest it needs.

    zipfile reads the central directory in one ``read`` of its declared size; entries are read
    :data:`CHUNK_BYTES` at a time, and local headers are at most 64 kB.
    """

    def __init__(self, raw: bytes | bytearray) -> None:
        super().__init__(raw)
        self.size = len(raw)

    def read(self, size: int | None = -1) -> bytes:
        left = self.size - self.tell()
        if min(left, size if size is not None and size >= 0 else left) > MAX_DIRECTORY_BYTES:
            raise CheckpointError(f"its directory is longer than {MAX_DIRECTORY_BYTES:,} bytes")
        return super().read(size)


class BoundedZip:
    """A zip archive held in memory, whose entries may inflate to ``budget`` bytes in all.

    Args:
        raw: the archive's bytes.
        where: what to name in messages (the file, ``model.zip: policy.pth``...).
        budget: the most bytes all entries read may inflate to; :attr:`left` says what is left.
        max_entries: the most entries the archive may hold.
        what: what the archive should be, for "not a readable <what> (why); <hint>".
        hint: what to do about a damaged archive (a limit passed ends in "refused").
        spent: what of ``budget`` was spent before (on the entries of other archives).

    Raises:
        CheckpointError: not a zip archive, too many entries, a directory over
            :data:`MAX_DIRECTORY_BYTES`, a name twice, an encrypted entry or another method.

    """

    def __init__(
        self,
        raw: bytes | bytearray,
        where: str,
        budget: int,
        max_entries: int,
        what: str = "zip archive",
        hint: str = "refused",
        spent: int = 0,
    ) -> None:
        self.where, self.what, self.hint = where, what, hint
        self.budget, self.left = budget, budget - spent
        try:
            self.zip = zipfile.ZipFile(_Capped(raw))
        except CheckpointError as exc:
            raise CheckpointError(f"{where}: {exc}; refused") from None
        except _ZIP_ERRORS as exc:
            raise self._unreadable(exc) from None
        infos = self.zip.infolist()
        self.infos = {info.filename: info for info in infos}
        if len(infos) > max_entries:
            self._refuse(f"holds {len(infos):,} entries, more than {max_entries}")
        if len(self.infos) != len(infos):
            self._refuse("holds an entry twice")
        for info in infos:
            if info.flag_bits & 0x1:
                self._refuse(f"{brief(info.filename)} is encrypted")
            if info.compress_type not in METHODS:
                self._refuse(f"{brief(info.filename)} uses compression method {info.compress_type}")

    @property
    def names(self) -> list[str]:
        """The entries' names, in the archive's order."""
        return list(self.infos)

    def read(self, name: str, limit: int | None = None) -> bytearray:
        """The bytes of entry ``name``, at most ``limit`` of them and of what the budget has left.

        Raises:
            CheckpointError: no such entry, larger than that, or damaged.

        """
        if name not in self.infos:
            self._refuse(f"holds no {brief(name)} entry")
        out = bytearray()
        self._inflate(self.infos[name], limit, out.extend)
        return out

    def repack(self) -> io.BytesIO:
        """All entries, inflated under the budget, as a new archive of stored entries.

        A reader given the result (torch's) finds each entry exactly as long as its directory
        says: its bytes were counted here, and none is compressed.
        """
        out = io.BytesIO()
        try:
            with zipfile.ZipFile(out, "w") as packed:
                for info in self.infos.values():
                    with packed.open(zipfile.ZipInfo(info.filename), "w") as sink:
                        self._inflate(info, None, sink.write)
        except CheckpointError:
            raise
        except _ZIP_ERRORS as exc:
            raise self._unreadable(exc) from None
        out.seek(0)
        return out

    def _inflate(
        self, info: zipfile.ZipInfo, limit: int | None, sink: Callable[..., object]
    ) -> None:
        """Pass the bytes of ``info`` to ``sink`` in chunks, counted against limit and budget."""
        cap = self.left if limit is None else min(limit, self.left)
        name = brief(info.filename)
        too_large = (
            f"{name} is larger than {cap:,} bytes once inflated"
            if limit is not None and limit <= self.left
            else f"{name} takes the entries past {self.budget:,} bytes in all once inflated"
        )
        if info.file_size > cap:  # declared: refused before inflating anything
            self._refuse(too_large)
        count = 0
        try:
            with self.zip.open(info) as entry:
                while chunk := entry.read(min(CHUNK_BYTES, cap + 1 - count)):
                    count += len(chunk)
                    if count > cap:  # what it really holds, whatever it declared
                        self._refuse(too_large)
                    sink(chunk)
        except CheckpointError:
            raise
        except _ZIP_ERRORS as exc:
            raise self._unreadable(exc) from None
        self.left -= count

    def _refuse(self, why: str) -> None:
        raise CheckpointError(f"{self.where}: {why}; refused")

    def _unreadable(self, exc: BaseException) -> CheckpointError:
        return CheckpointError(
            f"{self.where}: not a readable {self.what} ({type(exc).__name__}: "
            f"{shorten(str(exc), 120)}); {self.hint}"
        )

    def close(self) -> None:
        """Close the archive (its bytes are freed with this object)."""
        self.zip.close()

    def __enter__(self) -> BoundedZip:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()
