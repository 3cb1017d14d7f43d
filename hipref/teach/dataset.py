"""The answers of every teaching session in a folder as one tidy table, with its data card.

One row per preference answer (feedback answers are not in it). The session files are read, never
changed: a line that is not a session header or a preference answer as `hipref.teach.preferences` writes
it is refused with the file and line named (a torn last line included: reopening the session in notebook
09 drops it). `COLUMNS` is the one description of the table: it orders the columns and writes the data
card. Time to answer is the `seconds` each answer records (from the pair on screen to the press); the
files hold no wall-clock timestamps.

    python -m hipref.teach.dataset FOLDER OUT

writes OUT/answers.csv, OUT/answers.parquet and the data card OUT/answers.md.
"""

from __future__ import annotations

import io
import json
import os
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from hipref.experiments.domains import domain_spec
from hipref.learners.queries import QUERY_RULES
from hipref.results import write_bytes, write_csv, write_text
from hipref.teach.config import LEARNERS, TEACHERS
from hipref.teach.preferences import ANSWERS
from hipref.teach.session import FORMAT
from hipref.teachers.preference import pair_labels

HEADER_FIELDS: tuple[str, ...] = ("domain", "true_parameter", "learner", "query_rule", "seed")
"""What the first line of a session file must give for its answers to be read."""
ANSWER_FIELDS: tuple[str, ...] = ("query", "candidates", "order", "shown", "answer", "label")
"""What every preference line must give."""


@dataclass(frozen=True)
class Column:
    """A column of the table, as the data card describes it."""

    name: str
    dtype: str
    unit: str
    values: str
    """The values it may take."""
    description: str


DOMAINS: tuple[str, ...] = ("wiping", "pushing")
_PARAMETER = ", ".join(f"{domain_spec(d).unit} ({d})" for d in DOMAINS)
_RANGE = "in the domain's range: " + ", ".join(
    f"{d} {domain_spec(d).candidates.low:g}-{domain_spec(d).candidates.high:g}" for d in DOMAINS
)

COLUMNS: tuple[Column, ...] = (
    Column(
        "participant",
        "string",
        "-",
        "any text",
        "Who answered: the header's `participant`, else the session file's name without .jsonl",
    ),
    Column("session", "string", "-", "a file name", "The session file under FOLDER the answer is read from"),
    Column(
        "teacher",
        "string",
        "-",
        f"{', '.join(TEACHERS)}, unknown",
        "A person or the scripted stand-in: the header's `teacher`, else the file name's first word "
        "(`<teacher>_<domain>_seed<seed>.jsonl`), else unknown",
    ),
    Column("domain", "string", "-", ", ".join(DOMAINS), "The world the clips show"),
    Column("true_parameter", "float", _PARAMETER, _RANGE, "The hidden truth: desk height or cube mass"),
    Column("learner", "string", "-", ", ".join(LEARNERS), "The learner the session told the answers"),
    Column("query_rule", "string", "-", ", ".join(QUERY_RULES), "How pairs were chosen"),
    Column("session_seed", "int", "-", ">= 0", "The session's seed (queries, layouts, sides)"),
    Column("query", "int", "-", ">= 0", "The query's place in the session, from 0"),
    Column("candidate_a", "float", _PARAMETER, _RANGE, "The pair's first candidate, in the learner's order"),
    Column("candidate_b", "float", _PARAMETER, _RANGE, "The pair's second candidate"),
    Column("shown_left", "float", _PARAMETER, _RANGE, "The candidate whose clip was on the left"),
    Column("shown_right", "float", _PARAMETER, _RANGE, "The candidate whose clip was on the right"),
    Column("distance", "float", _PARAMETER, ">= 0", "The distance between the candidates, absolute"),
    Column("answer", "string", "-", ", ".join(ANSWERS), "What was pressed"),
    Column(
        "label",
        "int",
        "-",
        "1, -1, empty",
        "Eq. 2's label: 1 candidate_a preferred, -1 candidate_b, empty: can't tell",
    ),
    Column("chosen", "float", _PARAMETER, f"{_RANGE}; empty: can't tell", "The candidate preferred"),
    Column(
        "closer",
        "float",
        _PARAMETER,
        f"{_RANGE}; empty: both equally near",
        "The candidate nearer the truth (the scripted teacher's clean answer)",
    ),
    Column(
        "agrees",
        "boolean",
        "-",
        "True, False, empty",
        "chosen == closer; empty for can't tell or a pair equally near the truth",
    ),
    Column(
        "seconds",
        "float",
        "s",
        ">= 0; empty if not recorded",
        "Time to answer, as recorded: from the pair on screen to the press",
    ),
    Column(
        "catch_trial",
        "boolean",
        "-",
        "True, False",
        "A catch trial (a pair far apart), as the answer's `catch` flag says; false when not recorded",
    ),
)
NAMES: tuple[str, ...] = tuple(c.name for c in COLUMNS)
_READ: tuple[str, ...] = ("query", "candidate_a", "candidate_b", "shown_left", "shown_right", "answer")
_READ = (*_READ, "label", "chosen", "seconds", "catch_trial")
"""The columns read from each answer line; the rest come from the header or are derived."""


class SessionFormatError(ValueError):
    """A session file that cannot be read, naming the file and line."""


def _fail(path: Path, line: int, reason: str) -> SessionFormatError:
    return SessionFormatError(f"{path}, line {line}: {reason}")


def _parse(path: Path) -> list[tuple[int, dict[str, Any]]]:
    """Every line of `path` as (line number, JSON object)."""
    parsed = []
    text = path.read_text(encoding="utf-8")
    for number, line in enumerate(text.splitlines(), start=1):
        try:
            value = json.loads(line)
        except json.JSONDecodeError as error:
            torn = " (the last line, cut off while it was written: reopen the session to drop it)"
            last = number == len(text.splitlines()) and not text.endswith("\n")
            raise _fail(path, number, f"not JSON ({error.msg}){torn if last else ''}") from None
        if not isinstance(value, dict):
            raise _fail(path, number, f"a JSON object was expected, got {type(value).__name__}")
        parsed.append((number, value))
    if not parsed:
        raise _fail(path, 1, "empty file: no session header")
    return parsed


def _check_header(path: Path, header: dict[str, Any]) -> None:
    if header.get("format") != FORMAT:
        raise _fail(path, 1, f"not a session header (format {header.get('format')!r}, expected {FORMAT!r})")
    missing = [f for f in HEADER_FIELDS if f not in header]
    if missing:
        raise _fail(path, 1, f"the session header lacks {', '.join(missing)}")
    if header["domain"] not in DOMAINS:
        raise _fail(path, 1, f"unknown domain {header['domain']!r}")


def _check_answer(path: Path, number: int, record: dict[str, Any]) -> None:
    missing = [f for f in ANSWER_FIELDS if f not in record]
    if missing:
        raise _fail(path, number, f"a preference answer lacks {', '.join(missing)}")
    pair, order, shown = record["candidates"], record["order"], record["shown"]
    if not all(isinstance(v, list) for v in (pair, order, shown)):
        raise _fail(path, number, "candidates, order and shown must be lists")
    numeric = all(isinstance(v, int | float) and not isinstance(v, bool) for v in [*pair, *shown])
    if not (len(pair) == 2 and sorted(order) == [0, 1] and numeric and shown == [pair[i] for i in order]):
        raise _fail(path, number, f"candidates {pair}, order {order} and shown {shown} are not one pair")
    if record["answer"] not in ANSWERS:
        raise _fail(path, number, f"answer {record['answer']!r} is not one of {', '.join(ANSWERS)}")
    side = {"left": 0, "right": 1}.get(record["answer"])
    expected = None if side is None else (1 if order[side] == 0 else -1)
    if record["label"] != expected:
        raise _fail(path, number, f"label {record['label']!r} contradicts answer {record['answer']!r}")
    seconds = record.get("seconds")
    if seconds is not None and not (isinstance(seconds, int | float) and seconds >= 0):
        raise _fail(path, number, f"seconds {seconds!r} is not a time >= 0")


def _teacher(path: Path, header: dict[str, Any]) -> str:
    if "teacher" in header:
        return str(header["teacher"])
    if header.get("participant"):  # `make teach`'s sessions: a person's
        return "person"
    first = path.stem.split("_")[0]
    return first if first in TEACHERS else "unknown"


def read_records(path: str | os.PathLike[str]) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """A session file's header and its preference answers, checked line by line (read only)."""
    path = Path(path)
    lines = _parse(path)
    header = lines[0][1]
    _check_header(path, header)
    records = []
    for number, record in lines[1:]:
        if record.get("kind") == "preference":
            _check_answer(path, number, record)
            records.append(record)
    return header, records


def read_session(path: str | os.PathLike[str]) -> pd.DataFrame:
    """One session file's preference answers as rows of the table (`COLUMNS`)."""
    path = Path(path)
    header, records = read_records(path)
    rows = []
    for record in records:
        (a, b), label = record["candidates"], record["label"]
        rows.append(
            {
                "query": record["query"],
                "candidate_a": float(a),
                "candidate_b": float(b),
                "shown_left": float(record["shown"][0]),
                "shown_right": float(record["shown"][1]),
                "answer": record["answer"],
                "label": label,
                "chosen": np.nan if label is None else float(a if label == 1 else b),
                "seconds": record.get("seconds"),
                "catch_trial": bool(record.get("catch", False)),
            }
        )
    frame = pd.DataFrame(rows, columns=_READ)
    truth = float(header["true_parameter"])
    clean, tie = pair_labels(
        frame["candidate_a"].to_numpy(float), frame["candidate_b"].to_numpy(float), truth
    )
    closer = np.where(clean == 1, frame["candidate_a"], frame["candidate_b"]).astype(float)
    frame["closer"] = np.where(tie, np.nan, closer)
    # Candidates are a grid's values: the distance is rounded to the grid, not to the last bit.
    frame["distance"] = (frame["candidate_a"] - frame["candidate_b"]).abs().round(9)
    judged = frame["label"].notna().to_numpy() & ~tie
    frame["agrees"] = pd.array(np.where(judged, frame["chosen"] == frame["closer"], None), dtype="boolean")
    frame["participant"] = str(header.get("participant", path.stem))
    frame["session"] = path.name
    frame["teacher"] = _teacher(path, header)
    frame["domain"] = header["domain"]
    frame["true_parameter"] = truth
    frame["learner"] = header["learner"]
    frame["query_rule"] = header["query_rule"]
    frame["session_seed"] = int(header["seed"])
    return _typed(frame[list(NAMES)])


_DTYPES = {"string": "string", "float": "float64", "int": "Int64", "boolean": "boolean"}


def _typed(frame: pd.DataFrame) -> pd.DataFrame:
    return frame.astype({c.name: _DTYPES[c.dtype] for c in COLUMNS})


def read_sessions(folder: str | os.PathLike[str]) -> pd.DataFrame:
    """The answers of every session file (*.jsonl) in `folder`, files in name order, as one table."""
    folder = Path(folder)
    if not folder.is_dir():
        raise FileNotFoundError(f"no sessions folder {folder}")
    paths = sorted(folder.glob("*.jsonl"))
    if not paths:
        raise ValueError(f"{folder} holds no session files (*.jsonl)")
    return pd.concat([read_session(p) for p in paths], ignore_index=True)


def data_card(table: pd.DataFrame, source: str) -> str:
    """The table's data card (markdown): what it holds and every column's type, unit and values."""
    missing = [c for c in NAMES if c not in table.columns]
    if missing:
        raise ValueError(f"the table lacks the columns {missing} of the data card")
    seconds = (
        "every answer" if table["seconds"].notna().all() else f"{table['seconds'].notna().sum()} answers"
    )
    lines = [
        "# Answers of the teaching sessions",
        "",
        f"Exported from the session files of `{source}` by `python -m hipref.teach.dataset`: "
        f"{len(table)} preference answers (one a row) of {table['participant'].nunique()} participants in "
        f"{table['session'].nunique()} sessions. Feedback answers are not in the table. Time to answer is "
        f"recorded for {seconds}; the files hold no wall-clock timestamps. Empty cells are missing values.",
        "",
        "| column | type | unit | values | meaning |",
        "|---|---|---|---|---|",
        *(f"| `{c.name}` | {c.dtype} | {c.unit} | {c.values} | {c.description} |" for c in COLUMNS),
        "",
    ]
    return "\n".join(lines)


def export(folder: str | os.PathLike[str], out: str | os.PathLike[str]) -> pd.DataFrame:
    """Write the answers of `folder`'s sessions to `out`/answers.csv, answers.parquet and the data card
    answers.md; returns the table."""
    table = read_sessions(folder)
    out = Path(out)
    write_csv(table, out / "answers.csv")
    buffer = io.BytesIO()
    table.to_parquet(buffer, engine="pyarrow", index=False)
    write_bytes(buffer.getvalue(), out / "answers.parquet")
    write_text(data_card(table, Path(folder).name), out / "answers.md")
    return table


def main(argv: Sequence[str] | None = None) -> int:
    arguments = list(sys.argv[1:] if argv is None else argv)
    if len(arguments) != 2 or arguments[0].startswith("-"):
        print("usage: python -m hipref.teach.dataset FOLDER OUT", file=sys.stderr)
        print(__doc__.split("\n\n")[0], file=sys.stderr)
        return 2
    try:
        table = export(*arguments)
    except (OSError, ValueError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 1
    print(f"{len(table)} answers of {table['participant'].nunique()} participants -> {arguments[1]}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
