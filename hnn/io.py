"""Atomic writes: a reader sees the old file (or folder) or the new one, never a partial one.

    write_json(path, {"a": 1})
    atomic_write(path, lambda tmp: np.savez(tmp, x=x))
    atomic_folder(path, lambda tmp: write_json(tmp / "a.json", {}))   # a whole folder at once
    atomic_write(path, lambda tmp: Path(tmp).write_bytes(torch_bytes(state)))   # torch.save's bytes

A write that fails (a full disk, a folder made read-only) leaves no temporary file or folder and
raises ``WriteError``, an ``OSError`` whose message names the folder, the cause and the fix (a
``train.py`` prints it as one ``error:`` line). torch's own writer reports a full disk as a
``RuntimeError`` from its C++ code ("unexpected pos"), so torch objects are serialized in memory
first (``torch_bytes``) and written as plain bytes. Used by saved runs (``hnn.runs``) and the dataset
cache (``hnn.cache``); it imports nothing of ``hnn``, so either can use it without loading the other.
"""
from __future__ import annotations

import io
import json
import os
import shutil
import tempfile
from pathlib import Path

# the process's umask (read once: os.umask can only be read by setting it); files and folders made
# through temporary names get the permissions an ordinary open/mkdir would give them
UMASK = os.umask(0)
os.umask(UMASK)


class WriteError(OSError):
    """A file or folder could not be written (a full disk, a read-only folder): ``errno`` is the cause's,
    the message names the folder, the cause and the fix. Nothing half-written is left behind."""


def _write_failed(err: OSError, folder: Path) -> WriteError:
    cause = err.strerror or str(err)
    return WriteError(err.errno, f"cannot write in {folder}: {cause}; nothing half-written was left there. Free "
                                 "space on that disk, or write elsewhere (a train.py's --save_dir, a study's --out)")


def torch_bytes(obj) -> bytes:
    """``torch.save(obj)``'s bytes, made in memory (a failing write then raises ``OSError``, not torch's
    ``RuntimeError``)."""
    import torch
    buffer = io.BytesIO()
    torch.save(obj, buffer)
    return buffer.getvalue()


def atomic_write(path, write) -> None:
    """Call ``write(tmp_path)`` then rename onto ``path``, so readers never see a partial file; a write
    that fails raises ``WriteError`` naming the folder, and removes the temporary file."""
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    except OSError as err:
        raise _write_failed(err, path.parent) from err
    os.close(fd)
    try:
        write(tmp)
        os.chmod(tmp, 0o666 & ~UMASK)     # mkstemp makes 0600; give the file the usual permissions
        os.replace(tmp, path)
    except BaseException as err:
        Path(tmp).unlink(missing_ok=True)
        if isinstance(err, OSError) and not isinstance(err, WriteError):
            raise _write_failed(err, path.parent) from err
        raise


def write_json(path, obj) -> None:
    """``obj`` as indented JSON at ``path``, atomically."""
    atomic_write(path, lambda tmp: Path(tmp).write_text(json.dumps(obj, indent=2) + "\n"))


def atomic_folder(path: Path, fill) -> None:
    """Call ``fill(tmp)`` on a new hidden sibling folder ``.<name>.tmp-*``, then rename it to ``path``.

    A folder already at ``path`` is renamed aside to ``.<name>.old-*`` first and deleted after,
    so a crash at any moment leaves at ``path`` the old folder, the new one or nothing.
    """
    prefix = f".{path.name}.tmp-"
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(dir=path.parent, prefix=prefix))
    except OSError as err:
        raise _write_failed(err, path.parent) from err
    aside = path.parent / f".{path.name}.old-{tmp.name[len(prefix):]}"   # unique while tmp exists
    try:
        os.chmod(tmp, 0o777 & ~UMASK)     # mkdtemp makes 0700; give the folder the usual permissions
        fill(tmp)
        _move_in(tmp, path, aside)
    except BaseException as err:
        shutil.rmtree(tmp, ignore_errors=True)
        if isinstance(err, OSError) and not isinstance(err, WriteError):
            raise _write_failed(err, path.parent) from err
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
