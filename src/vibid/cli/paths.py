"""Output paths checked before any long work starts, with errors that name the user's path.

A command that would write ``--json``, ``--out`` or a report at the end of a long run calls
:func:`check_output_file` (or :func:`check_output_dir`) first, so a typo in a folder name costs
a second, not the identification. Whether the folder is writable is tried, not guessed from
permission bits (root, read-only file systems, network shares).
"""

from __future__ import annotations

import os
import tempfile

from vibid.errors import VibidError


def check_output_file(path: str | os.PathLike, *, overwrite: bool) -> None:
    """Raise :class:`VibidError` unless a file can be written at ``path``.

    Parameters
    ----------
    path : the file the command will write, as the user gave it.
    overwrite : whether an existing file there may be replaced (reports: yes; session files:
        never).
    """
    shown = os.fspath(path)
    if os.path.isdir(shown):
        raise VibidError(f"{shown}: is a directory; give a file name")
    if os.path.lexists(shown):
        if not overwrite:
            raise VibidError(f"{shown}: already exists; a session file is never overwritten")
        if not os.access(shown, os.W_OK):
            raise VibidError(f"{shown}: cannot be overwritten (permission denied)")
    folder = os.path.dirname(os.path.abspath(shown))
    if not os.path.isdir(folder):
        raise VibidError(f"{shown}: cannot write: the folder {folder} does not exist")
    _try_writing_in(folder, shown)


def check_output_dir(path: str | os.PathLike) -> None:
    """Make folder ``path`` (and its parents) if needed; raise :class:`VibidError` unless files
    can be written in it."""
    shown = os.fspath(path)
    if os.path.exists(shown) and not os.path.isdir(shown):
        raise VibidError(f"{shown}: exists and is not a folder")
    try:
        os.makedirs(shown, exist_ok=True)
    except OSError as exc:
        raise VibidError(f"{shown}: cannot make the folder ({exc.strerror})") from None
    _try_writing_in(shown, shown)


def _try_writing_in(folder: str, shown: str) -> None:
    try:
        with tempfile.TemporaryFile(dir=folder):
            pass
    except OSError as exc:
        where = "this folder" if folder == shown else folder
        raise VibidError(
            f"{shown}: cannot write in {where} ({exc.strerror or 'not writable'})"
        ) from None
