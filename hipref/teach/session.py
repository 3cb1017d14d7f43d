"""A teaching session's answers file: JSON Lines, one answer a line, each written before it is used.

The first line describes the session (its config); every later line is one answer, appended with a single
`write` on a file opened for appending and synced to disk before the learner is told. A killed kernel
therefore loses nothing that was answered: at worst the line being written when it died is torn, and a
torn last line (no newline, or not JSON) is dropped when the file is read again, with a warning, before
anything more is appended. Reopening a session replays its answers (`hipref.teach.preferences`,
`hipref.teach.feedback`), so the learners are rebuilt and the next query is the one that would have come.
"""

from __future__ import annotations

import json
import os
import warnings
from collections.abc import Mapping
from pathlib import Path
from typing import Any

FORMAT = "hipref-teaching-session/1"
"""The first line's `format`: what a reader of the file can expect."""


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
        self.path.parent.mkdir(parents=True, exist_ok=True)
        if fresh or not self.path.exists() or self.path.stat().st_size == 0:
            self._write_new()
            return
        lines = self._read_lines()
        stored = lines[0] if lines else None
        if stored != self.header:
            differ = sorted(
                k for k in {*self.header, *(stored or {})} if (stored or {}).get(k) != self.header.get(k)
            )
            raise ValueError(
                f"{self.path} holds another session (fields {', '.join(differ)} differ from this one's): "
                "choose another session file, or start this one afresh"
            )
        self.records = lines[1:]

    def _write_new(self) -> None:
        temporary = self.path.with_name(self.path.name + ".new")
        temporary.write_text(json.dumps(self.header, sort_keys=True) + "\n")
        os.replace(temporary, self.path)

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

    def append(self, record: Mapping[str, Any]) -> None:
        """Write `record` as one line and sync it to disk; only then is it in `records`."""
        line = (json.dumps(record, sort_keys=True) + "\n").encode()
        descriptor = os.open(self.path, os.O_WRONLY | os.O_APPEND)
        try:
            os.write(descriptor, line)
            os.fsync(descriptor)
        finally:
            os.close(descriptor)
        self.records.append(json.loads(line))

    def of_kind(self, kind: str) -> list[dict[str, Any]]:
        """The records of one kind ('preference' or 'feedback'), in order."""
        return [record for record in self.records if record.get("kind") == kind]
