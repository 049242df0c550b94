"""How ``paz6d`` reports bad input: one line ``paz6d <command>: error: <what>``, exit code 2, no traceback.

Readers raise ``ValueError`` naming the file and field; :data:`EXPECTED_ERRORS` are the other
failures bad input or a bad environment can cause (a folder where a file is expected, a full disk,
a truncated ``.npz``, a malformed CSV, JSON nested too deeply), which :func:`describe` turns into
the same kind of line. Messages are shortened (:func:`shorten`), so a 5 MB value in an input file is
never echoed whole.
"""

from __future__ import annotations

import csv
import errno
import zipfile

#: Longest message printed (characters); longer ones keep their start and end.
MESSAGE_LIMIT = 1000
#: Longest repr of a missing key quoted in a message.
VALUE_LIMIT = 80

#: Errors that bad input or environment cause; anything else is a bug and keeps its traceback.
EXPECTED_ERRORS = (ValueError, OSError, KeyError, csv.Error, zipfile.BadZipFile, RecursionError, EOFError,
                   MemoryError)


def shorten(text: str, limit: int = MESSAGE_LIMIT) -> str:
    """``text`` unchanged when at most ``limit`` characters, else its start and end around
    ``"... [N characters left out] ..."``."""
    if len(text) <= limit:
        return text
    keep = max(limit - 40, 20)
    head, tail = text[:keep * 3 // 4], text[len(text) - keep // 4:]
    return f"{head} ... [{len(text) - len(head) - len(tail)} characters left out] ... {tail}"


def describe(error: BaseException) -> str:
    """A one-line description of an expected error (see :data:`EXPECTED_ERRORS`), naming the file
    when the error knows it."""
    if isinstance(error, OSError):
        reason = error.strerror or str(error) or type(error).__name__
        if error.errno == errno.ENOSPC:
            reason = "no space left on device"
        names = [name for name in (error.filename, error.filename2) if name is not None]
        return f"{' -> '.join(map(str, names))}: {reason}" if names else reason
    if isinstance(error, KeyError):
        key = shorten(repr(error.args[0]), VALUE_LIMIT) if error.args else ""
        return f"missing entry {key} (incomplete or corrupt input)"
    if isinstance(error, zipfile.BadZipFile):
        return f"corrupt or truncated archive (.npz/.keras): {error}"
    if isinstance(error, RecursionError):
        return "input nested too deeply to read (maximum recursion depth exceeded)"
    if isinstance(error, csv.Error):
        return f"malformed CSV: {error}"
    if isinstance(error, EOFError):
        return f"file ended early (truncated input){': ' + str(error) if str(error) else ''}"
    if isinstance(error, MemoryError):
        return "out of memory (an input is too large)"
    return str(error) or type(error).__name__


def report(command: str, error: BaseException) -> str:
    """The line printed for ``error`` raised by ``paz6d <command>``."""
    return shorten(f"paz6d {command}: error: {describe(error)}").replace("\n", " ")
