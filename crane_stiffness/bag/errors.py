"""Errors and warnings of :mod:`crane_stiffness.bag`.

Every exception derives from :class:`BagError` (itself a :class:`~crane_stiffness.errors.CraneStiffnessError`), so a
caller can catch all bag problems with one ``except``. Damage that the reader can work around (a truncated file, a
chunk whose checksum does not match) is reported with a :class:`BagDamageWarning` and the readable part is used.
"""

from __future__ import annotations

from crane_stiffness.errors import CraneStiffnessError


class BagError(CraneStiffnessError):
    """Base class of every error raised by the bag package."""


class BagFormatError(BagError):
    """A file is not an MCAP file, or its structure is too damaged to read anything."""


class BagCorruptError(BagFormatError):
    """A part of a file is damaged (bad checksum, impossible record); raised instead of warning when strict."""


class BagUnsupportedError(BagFormatError):
    """A file is valid but uses something this reader cannot interpret (a chunk compression, a message or schema
    encoding); the message names the file and the value."""


class BagNotFoundError(BagError, FileNotFoundError):
    """The bag directory, metadata.yaml or .mcap file does not exist."""


class BagExistsError(BagError, FileExistsError):
    """The writer's target directory already holds files."""


class BagWriterError(BagError):
    """Misuse of the writer: unknown topic, write after close, bad option."""


class BagWriteFailedError(BagError):
    """The operating system refused a write of the bag (disk full, I/O error, file system gone).

    The writer stops at the first such error: the file it was writing is cut back to its last complete record, so
    every chunk written before stays readable, and the writer accepts no more messages. ``path`` is the file whose
    write failed, ``errno`` the OS error number (``errno.ENOSPC`` for a full disk).
    """

    def __init__(self, message: str, path: object = None, errno: int | None = None) -> None:
        super().__init__(message)
        self.path = path
        self.errno = errno


def os_error_text(exc: OSError) -> str:
    """``[Errno 28] No space left on device`` (without the file name str(OSError) may carry)."""
    return f'[Errno {exc.errno}] {exc.strerror}' if exc.errno is not None else str(exc)


class BagPathError(BagFormatError):
    """A bag names a file outside its own directory (``..``, an absolute path, a symlink leading out)."""


class TopicNotFoundError(BagError, KeyError):
    """A requested topic is not in the bag; the message names the topics that are."""

    def __str__(self) -> str:  # KeyError would quote the message
        return str(self.args[0]) if self.args else ''


class UnsupportedTypeError(BagError):
    """The bulk decoder has no fixed-layout decoder for this message type."""


class MessageDefinitionError(BagError):
    """A .msg definition could not be found or parsed under the ament prefixes."""


class BagDamageWarning(UserWarning):
    """Part of a bag could not be read (truncated file, bad chunk); the readable part was used."""
