"""Atomic writes: a reader sees the old file (or folder) or the new one, never a partial one.

    write_json(path, {"a": 1})
    atomic_write(path, lambda tmp: np.savez(tmp, x=x))
    atomic_folder(path, lambda tmp: write_json(tmp / "a.json", {}))   # a whole folder at once

Used by saved runs (``hnn.runs``) and the dataset cache (``hnn.cache``); it imports nothing of
``hnn``, so either can use it without loading the other.
"""
from __future__ import annotations

import json
import os
import shutil
import tempfile
from pathlib import Path

# the process's umask (read once: os.umask can only be read by setting it); files and folders made
# through temporary names get the permissions an ordinary open/mkdir would give them
UMASK = os.umask(0)
os.umask(UMASK)


def atomic_write(path, write) -> None:
    """Call ``write(tmp_path)`` then rename onto ``path``, so readers never see a partial file."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    os.close(fd)
    try:
        write(tmp)
        os.chmod(tmp, 0o666 & ~UMASK)     # mkstemp makes 0600; give the file the usual permissions
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def write_json(path, obj) -> None:
    """``obj`` as indented JSON at ``path``, atomically."""
    atomic_write(path, lambda tmp: Path(tmp).write_text(json.dumps(obj, indent=2) + "\n"))


def atomic_folder(path: Path, fill) -> None:
    """Call ``fill(tmp)`` on a new hidden sibling folder ``.<name>.tmp-*``, then rename it to ``path``.

    A folder already at ``path`` is renamed aside to ``.<name>.old-*`` first and deleted after,
    so a crash at any moment leaves at ``path`` the old folder, the new one or nothing.
    """
    path.parent.mkdir(parents=True, exist_ok=True)
    prefix = f".{path.name}.tmp-"
    tmp = Path(tempfile.mkdtemp(dir=path.parent, prefix=prefix))
    aside = path.parent / f".{path.name}.old-{tmp.name[len(prefix):]}"   # unique while tmp exists
    try:
        os.chmod(tmp, 0o777 & ~UMASK)     # mkdtemp makes 0700; give the folder the usual permissions
        fill(tmp)
        _move_in(tmp, path, aside)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


def _move_in(tmp: Path, path: Path, aside: Path) -> None:
    """Rename folder ``tmp`` to ``path``, replacing (via ``aside``) any folder there."""
    try:
        os.rename(path, aside)
        replaced = True
    except FileNotFoundError:
        replaced = False
    try:
        os.rename(tmp, path)
    except BaseException:
        if replaced:
            os.rename(aside, path)    # the old run back where it was
        raise
    if replaced:
        shutil.rmtree(aside, ignore_errors=True)


def check_save_dir(save_dir) -> None:
    """Raise ValueError naming ``save_dir`` and the fix when run folders cannot be written there
    (it is a file, or it cannot be created or written); creates it otherwise."""
    path = Path(save_dir)
    if path.exists() and not path.is_dir():
        raise ValueError(f"save_dir {save_dir}: is a file, not a folder; pass a folder (it is created if missing)")
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise ValueError(f"save_dir {save_dir}: cannot create it ({err.strerror or err}); pass a folder you can "
                         "write") from None
    if not os.access(path, os.W_OK | os.X_OK):
        raise ValueError(f"save_dir {save_dir}: not writable; pass a folder you can write")
