"""The sweep cache's entries on disk: what one holds, when it is used, and the directory they go in.

An entry carries the key it was stored under and a checksum of its payload, which must match when it is
read back: a damaged, stale, moved or foreign pickle is recomputed with a warning, never used. A cache
directory that cannot be written is refused before any compute. Only the standard library is imported at
load time.
"""

from __future__ import annotations

import hashlib
import os
import pickle
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

from hipref.results import write_bytes

_ENTRY_FORMAT = "hipref-cache-1"
"""Marks a cache entry: a pickled dict of this format, the key it was stored under, the sha256 of its
payload and the payload (the pickled value)."""


def write_entry(path: Path, key: str, value: Any) -> None:
    """Store `value` at `path` (atomically) as an entry of `key`."""
    payload = pickle.dumps(value, protocol=pickle.HIGHEST_PROTOCOL)
    entry = {
        "format": _ENTRY_FORMAT,
        "key": key,
        "sha256": hashlib.sha256(payload).hexdigest(),
        "payload": payload,
    }
    write_bytes(pickle.dumps(entry, protocol=pickle.HIGHEST_PROTOCOL), path)


def read_entry(path: Path) -> tuple[str, Any]:
    """(key, value) of the entry at `path`; ValueError when it is no intact entry."""
    with path.open("rb") as f:
        entry = pickle.load(f)
    if not (isinstance(entry, dict) and entry.get("format") == _ENTRY_FORMAT):
        raise ValueError(
            f"it is no cache entry (a bare {type(entry).__name__}, without the key it was stored under)"
        )
    payload = entry["payload"]
    if hashlib.sha256(payload).hexdigest() != entry["sha256"]:
        raise ValueError("its payload does not match its checksum")
    return entry["key"], pickle.loads(payload)


def load_entry(
    path: Path | None, key: str, problem: Callable[[Any], str | None] | None = None
) -> tuple[bool, Any]:
    """Read the cache entry of `key`; (False, None) when there is no cache (`path` None), the entry is
    absent, unreadable, stored under another key or, by `problem`, not what it should hold, with a warning
    in the last three cases."""
    if path is None or not path.exists():
        return False, None
    try:
        stored, value = read_entry(path)
    except Exception as err:
        reason: str | None = f"it is unreadable: {err}"
    else:
        if stored != key:
            reason = f"it was stored under the key {stored[:16]}..., not this entry's {key[:16]}..."
        else:
            reason = None if problem is None else problem(value)
    if reason is not None:
        warnings.warn(f"ignoring cache entry {path}: {reason}; recomputing it", stacklevel=3)
        return False, None
    return True, value


def check_writable(cache: Path | None, part: str) -> None:
    """Refuse, before any compute, a cache directory whose `part` (cells, artefacts) cannot take entries:
    not creatable, not a directory, or not writable (a file written and removed in it proves it)."""
    if cache is None:
        return
    directory = cache / part
    try:
        directory.mkdir(parents=True, exist_ok=True)
        probe = directory / f".write-check.{os.getpid()}.tmp"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as err:
        raise PermissionError(
            f"the cache directory {directory} cannot be written ({err.strerror or err}); set "
            "HIPREF_CACHE_DIR (or cache_dir=) to a writable directory, or pass cache_dir=NO_CACHE"
        ) from None
