"""A teaching session's answers file: JSON Lines, one answer a line, each written before it is used.

The first line describes the session (its config); every later line is one answer, appended with a single
`write` on a file opened for appending and synced to disk before the learner is told. A killed kernel
therefore loses nothing that was answered: at worst the line being written when it died is torn, and a
torn last line (no newline, or not JSON) is dropped when the file is read again, with a warning, before
anything more is appended. Reopening a session replays its answers (`hipref.teach.preferences`,
`hipref.teach.feedback`), so the learners are rebuilt and the next query is the one that would have come.

A person cannot spoil the file:

- every answer carries the number of the query it answers (`ANSWER_IDS`), and an answer to a query that
  already has one, or that skips one, is refused (`AnswerRefused`) before anything is written;
- one writer per file: opening a session takes an exclusive lock (`fcntl.flock` on `<file>.lock`, which
  names its holder), held until the session is closed or its process ends. Another process opening the
  same file gets `SessionLocked` naming the holder's pid and host; opening it again in the same process
  hands the lock to the newer session, and the older one refuses to write;
- the file is opened for appending when the session opens, so a file that cannot be written is reported
  before the first query is shown (`SessionUnwritable`), not at the first answer.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import json
import os
import socket
import time
import warnings
from collections.abc import Mapping
from pathlib import Path
from typing import Any

FORMAT = "hipref-teaching-session/1"
"""The first line's `format`: what a reader of the file can expect."""
ANSWER_IDS: dict[str, str] = {"preference": "query", "feedback": "step"}
"""The field of an answer of each kind that numbers the query it answers, from 0."""


class AnswerRefused(ValueError):
    """An answer the file cannot take: its query was already answered, or one before it was not."""


class OtherSession(ValueError):
    """The file holds a session started with another header: `stored` is its header, `differ` the fields
    that differ from this one's."""

    def __init__(self, message: str, stored: dict[str, Any], differ: list[str]) -> None:
        super().__init__(message)
        self.stored = stored
        self.differ = differ


class SessionLocked(RuntimeError):
    """The session file is being written by another live session."""


class SessionUnwritable(OSError):
    """The session file (or its folder) cannot be written: answers could not be saved."""


_HOLDERS: dict[Path, SessionFile] = {}
"""The live session of each file in this process (the holder of its lock)."""


class SessionFile:
    """The answers of one session, on disk and in memory (`records`, in the order given)."""

    def __init__(
        self, path: str | os.PathLike[str], header: Mapping[str, Any], *, fresh: bool = False
    ) -> None:
        """Open the session at `path`, or start it with `header` (the session's config, plain data).

        An existing file must have been started with the same header, else ValueError names the fields
        that differ (answers given to another session cannot be replayed into this one). `fresh` replaces
        an existing file by a new session instead."""
        self.path = Path(path)
        self.header = {"format": FORMAT, **header}
        self.records: list[dict[str, Any]] = []
        self._descriptor: int | None = None
        self._lock: int | None = None
        self.superseded = False
        """True once a newer session of the same file was opened in this process: this one writes no more."""
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
        except OSError as error:
            raise self._unwritable(error) from error
        self._take_lock()
        try:
            self._open(fresh)
            self._descriptor = self._open_for_appending()
        except BaseException:
            self.close()
            raise

    def _open(self, fresh: bool) -> None:
        if fresh or not self.path.exists() or self.path.stat().st_size == 0:
            self._write_new()
            return
        lines = self._read_lines()
        stored = lines[0] if lines else None
        if stored != self.header:
            differ = sorted(
                k for k in {*self.header, *(stored or {})} if (stored or {}).get(k) != self.header.get(k)
            )
            raise OtherSession(
                f"{self.path} holds another session (fields {', '.join(differ)} differ from this one's): "
                "choose another session file, or start this one afresh",
                stored if isinstance(stored, dict) else {},
                differ,
            )
        for number, record in enumerate(lines[1:], start=2):
            try:
                self._check_next(record, self.records)
            except AnswerRefused as error:
                raise ValueError(
                    f"{self.path}, line {number}: {error} (the file was written by two sessions at once)"
                ) from None
            self.records.append(record)

    def _unwritable(self, error: OSError) -> SessionUnwritable:
        return SessionUnwritable(
            error.errno,
            f"the session file {self.path} cannot be written ({error.strerror or error}): no answer could be "
            "saved. Make the file and its folder writable (and the disk not full), or choose another session "
            "file",
        )

    def _take_lock(self) -> None:
        """The file's lock, or SessionLocked naming its holder; a session of this process hands it over."""
        key = self.path.resolve()
        older = _HOLDERS.pop(key, None)
        if older is not None:
            older.close()
            older.superseded = True
        lock_path = self.path.with_name(self.path.name + ".lock")
        try:
            self._lock = os.open(lock_path, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as error:
            raise self._unwritable(error) from error
        try:
            fcntl.flock(self._lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(self._lock, 512, 0).decode(errors="replace").strip() or "an unknown process"
            os.close(self._lock)
            self._lock = None
            raise SessionLocked(
                f"{self.path} is open in another live session ({holder}): only one session may write a "
                "session file. Close that one (shut down its kernel), or choose another session file"
            ) from None
        os.ftruncate(self._lock, 0)
        started = time.strftime("%Y-%m-%d %H:%M:%S %Z")
        holder = f"pid {os.getpid()} on host {socket.gethostname()}, since {started}"
        os.pwrite(self._lock, holder.encode(), 0)
        _HOLDERS[key] = self

    def _open_for_appending(self) -> int:
        try:
            return os.open(self.path, os.O_WRONLY | os.O_APPEND)
        except OSError as error:
            raise self._unwritable(error) from error

    def close(self) -> None:
        """Release the file and its lock; the session writes no more."""
        for descriptor in (self._descriptor, self._lock):
            if descriptor is not None:
                os.close(descriptor)  # closing the lock file's descriptor releases the flock
        self._descriptor = self._lock = None
        if _HOLDERS.get(self.path.resolve()) is self:
            del _HOLDERS[self.path.resolve()]

    def _write_new(self) -> None:
        temporary = self.path.with_name(self.path.name + ".new")
        try:
            temporary.write_text(json.dumps(self.header, sort_keys=True) + "\n")
            os.replace(temporary, self.path)
        except OSError as error:
            raise self._unwritable(error) from error

    def _read_lines(self) -> list[dict[str, Any]]:
        raw = self.path.read_bytes()
        complete, _, torn = raw.rpartition(b"\n")
        lines = []
        for number, line in enumerate(complete.split(b"\n") if complete else [], start=1):
            try:
                lines.append(json.loads(line))
            except json.JSONDecodeError:
                raise ValueError(f"{self.path}, line {number}: not a JSON answer record") from None
        if torn:
            warnings.warn(
                f"{self.path}: the last line was cut off when it was written (the session stopped while "
                f"writing it); it is dropped, {len(torn)} bytes",
                stacklevel=3,
            )
            with self.path.open("r+b") as file:
                file.truncate(len(complete) + 1 if complete else 0)
        return lines

    @staticmethod
    def _check_next(record: Mapping[str, Any], before: list[dict[str, Any]]) -> None:
        """AnswerRefused unless `record` answers the next query of its kind after the answers `before`."""
        kind = record.get("kind")
        if kind not in ANSWER_IDS:
            return
        field = ANSWER_IDS[kind]
        expected = next((r[field] + 1 for r in reversed(before) if r.get("kind") == kind), 0)
        given = record.get(field)
        if given == expected:
            return
        if isinstance(given, int) and given < expected:
            raise AnswerRefused(
                f"{kind} query {given} already has an answer in this session: a second answer to it is "
                "refused"
            )
        raise AnswerRefused(
            f"{kind} answer to {field} {given!r}, but the next unanswered query is {expected}"
        )

    def append(self, record: Mapping[str, Any]) -> None:
        """Write `record` as one line and sync it to disk; only then is it in `records`. An answer must
        answer the next query of its kind (AnswerRefused); a write that fails raises OSError, and the
        record is not kept (the answer may be given again)."""
        if self._descriptor is None:
            why = "a newer session of this file was opened in this process" if self.superseded else "closed"
            raise SessionLocked(f"{self.path}: this session is {why}; answer in the newest one")
        self._check_next(record, self.records)
        line = (json.dumps(record, sort_keys=True) + "\n").encode()
        size = os.fstat(self._descriptor).st_size
        try:
            written = os.write(self._descriptor, line)
            if written != len(line):
                raise OSError(errno.ENOSPC, "the line was written only in part")
            os.fsync(self._descriptor)
        except OSError:
            with contextlib.suppress(OSError):  # no partial line left behind to be read as an answer
                os.ftruncate(self._descriptor, size)
            raise
        self.records.append(json.loads(line))

    def of_kind(self, kind: str) -> list[dict[str, Any]]:
        """The records of one kind ('preference' or 'feedback'), in order."""
        return [record for record in self.records if record.get("kind") == kind]
