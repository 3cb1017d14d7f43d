"""Writing the study's results: tidy CSVs, figures, text and the shared claims file.

Every writer goes through `write_bytes`: the bytes land in a temporary file beside the target, then
`os.replace` swaps it in. A run interrupted at any point therefore leaves either the old file or the new
one, never half of one, as the results contract asks.

Only the standard library is imported at run time, so `hipref.sweep` (which uses `write_bytes` for its
cache) loads in a worker process before numpy does, and the worker's one-thread settings take effect.
"""

from __future__ import annotations

import contextlib
import fcntl
import io
import os
import re
import secrets
import tempfile
from collections.abc import Iterable, Iterator, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import hipref

if TYPE_CHECKING:
    import pandas as pd
    from matplotlib.figure import Figure

TIDY_COLUMNS: tuple[str, ...] = ("domain", "method", "noise", "seed", "episode", "metric", "value")
"""Columns every results frame has (more may follow, such as `ground_truth`)."""

METRICS: tuple[str, ...] = (
    "param_error",
    "param_error_argmax",
    "param_error_multislice",
    "median_error",
    "success_rate",
    "cells_wiped",
    "force_mean",
    "force_std",
    "estimated_noise",
    "true_noise",
    "filter_precision",
    "filter_recall",
    "imitation_mse",
    "goal_distance",
    "goal_overshoot",
    "goal_sideways",
    "true_model_probability",
)
"""The metric names a results frame may use; a study that measures something new adds it here."""


def tidy_rows(
    rows: Iterable[Sequence[object]],
    varying: Sequence[str] = ("episode", "metric", "value"),
    **constant: object,
) -> pd.DataFrame:
    """Rows of the results contract: each of `rows` gives the `varying` columns, `constant` the columns every
    row shares. The tidy columns (TIDY_COLUMNS) come first, then the others: the varying, then the
    constant ones, in the order given."""
    import pandas as pd

    frame = pd.DataFrame(list(rows), columns=list(varying)).assign(**constant)
    missing = [column for column in TIDY_COLUMNS if column not in frame.columns]
    if missing:
        raise ValueError(f"rows lack the tidy column(s) {missing}; tidy columns are {TIDY_COLUMNS}")
    extra = [column for column in [*varying, *constant] if column not in TIDY_COLUMNS]
    return frame[[*TIDY_COLUMNS, *extra]]


CLAIMS_HEADER = (
    "# Claims: the paper against this study\n"
    "\n"
    "Each section below is written by one notebook through `hipref.results.update_claims`; re-run the\n"
    "notebook rather than editing its section by hand.\n"
)

_NAME = re.compile(r"[A-Za-z0-9_.-]+")


def repo_root() -> Path | None:
    """The source checkout holding the package, or None when `hipref` is installed elsewhere."""
    root = Path(hipref.__file__).resolve().parent.parent
    return root if (root / "pyproject.toml").is_file() else None


def results_dir() -> Path:
    """Where results go: `$HIPREF_RESULTS_DIR`, else the checkout's `results/`, else `./results`.

    Anchored on the package rather than the working directory, so a notebook run by papermill with
    `--cwd notebooks` (or from anywhere) writes to the same place as `make reproduce`.
    """
    if env := os.environ.get("HIPREF_RESULTS_DIR"):
        return Path(env)
    root = repo_root()
    return (root if root is not None else Path.cwd()) / "results"


RESULT_FOLDERS: tuple[str, ...] = ("data", "figures", "tables")
"""Folders of the results directory the notebooks write into (claims.md sits at its top)."""


def check_writable(directory: str | os.PathLike[str] | None = None) -> Path:
    """Refuse, before any compute, a results directory the study cannot write; returns it.

    `directory` (default `results_dir()`) and its `RESULT_FOLDERS` are created if missing, and a probe
    file is written to and removed from each. Raises PermissionError naming the folder that fails and
    `HIPREF_RESULTS_DIR`, which moves the results elsewhere.
    """
    root = Path(results_dir() if directory is None else directory)
    for folder in (root, *(root / name for name in RESULT_FOLDERS)):
        try:
            folder.mkdir(parents=True, exist_ok=True)
            # A unique probe name, so notebooks checking the same folder side by side do not collide.
            fd, probe = tempfile.mkstemp(prefix=".write-check.", suffix=".tmp", dir=folder)
            os.close(fd)
            os.unlink(probe)
        except OSError as error:
            raise PermissionError(
                f"results directory {folder} is not writable ({error.strerror or error}); make it writable "
                "or set HIPREF_RESULTS_DIR to a writable directory"
            ) from error
    return root


def write_bytes(data: bytes, path: str | os.PathLike[str]) -> Path:
    """Write `data` to `path` atomically, creating parent directories; returns the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    # The temporary file sits in the same directory so that os.replace is a rename on one filesystem,
    # hence atomic. A hidden name ending in .tmp keeps it out of globs such as "*.csv" or "*.pkl".
    tmp = path.with_name(f".{path.name}.{os.getpid()}.{secrets.token_hex(4)}.tmp")
    try:
        # 0o666 through os.open applies the umask, so results get the usual permissions.
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
        with open(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


def write_text(text: str, path: str | os.PathLike[str]) -> Path:
    """Write UTF-8 text atomically."""
    return write_bytes(text.encode("utf-8"), path)


def write_csv(df: pd.DataFrame, path: str | os.PathLike[str]) -> Path:
    """Write a results frame as CSV atomically, without the index (tidy rows carry their own keys)."""
    return write_text(df.to_csv(index=False, lineterminator="\n"), path)


def save_figure(fig: Figure, path: str | os.PathLike[str], *, dpi: int = 150) -> Path:
    """Save a matplotlib figure as PNG atomically.

    The PNG carries no software-version metadata, so the same figure gives the same bytes whichever
    matplotlib release drew it.
    """
    if Path(path).suffix.lower() != ".png":
        raise ValueError(f"save_figure writes PNG files; path must end in .png, got {str(path)!r}")
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, bbox_inches="tight", metadata={"Software": None})
    return write_bytes(buf.getvalue(), path)


def check_tidy(df: pd.DataFrame, metrics: Iterable[str] | None = None) -> pd.DataFrame:
    """Check a results frame against the results contract and return it unchanged.

    Raises ValueError naming the first missing column, any metric outside `metrics` (default
    `METRICS`), or a noise level outside [0, 1] (noise is a fraction: 0.2, not 20).
    """
    for column in TIDY_COLUMNS:
        if column not in df.columns:
            raise ValueError(f"results frame lacks column {column!r}; tidy columns are {TIDY_COLUMNS}")
    allowed = set(METRICS if metrics is None else metrics)
    unknown = sorted(set(df["metric"].unique()) - allowed, key=str)
    if unknown:
        raise ValueError(f"unknown metric(s) {unknown}; allowed metrics are {sorted(allowed)}")
    noise = df["noise"].dropna()
    if len(noise) and not noise.between(0.0, 1.0).all():
        bad = noise[~noise.between(0.0, 1.0)].iloc[0]
        raise ValueError(f"noise must be a fraction of flipped labels in [0, 1], got {bad!r}")
    return df


def claims_table(rows: Iterable[Sequence[str]]) -> str:
    """A markdown table of (claim, what the paper says, what the study measured, holds) rows.

    `holds` is one of `hipref.verdicts.VERDICTS`: a claim that does not hold is reported as such.
    """
    from hipref.verdicts import VERDICTS

    lines = ["| Claim | Paper says | Study measured | Holds |", "| --- | --- | --- | --- |"]
    for row in rows:
        if len(row) != 4:
            raise ValueError(
                f"a claims row has 4 fields (claim, paper, study, holds), got {len(row)}: {row!r}"
            )
        *cells, holds = (str(cell) for cell in row)
        if holds not in VERDICTS:
            raise ValueError(f"holds must be one of {VERDICTS}, got {holds!r} for claim {cells[0]!r}")
        cells = [cell.replace("|", r"\|").replace("\n", " ").strip() for cell in [*cells, holds]]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


@contextlib.contextmanager
def _locked(directory: Path) -> Iterator[None]:
    """Hold an exclusive lock on `directory`, so notebooks run side by side do not lose each other's
    claims between reading and replacing the file (the lock needs no extra file in results/)."""
    fd = os.open(directory, os.O_RDONLY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)


def update_claims(section: str, markdown: str, path: str | os.PathLike[str] | None = None) -> Path:
    """Replace one notebook's section of the claims file (default `results_dir()/claims.md`).

    A section is delimited by `<!-- section: NAME -->` and `<!-- end: NAME -->`. Its body is replaced,
    or the section is inserted before the first section whose name sorts after it; every other byte of
    the file is kept, so one notebook never disturbs another's claims.
    """
    if not _NAME.fullmatch(section):
        raise ValueError(f"section name must match {_NAME.pattern}, got {section!r}")
    if "<!-- section:" in markdown or "<!-- end:" in markdown:
        raise ValueError("the markdown of a section cannot contain section markers")
    path = Path(results_dir() / "claims.md" if path is None else path)
    path.parent.mkdir(parents=True, exist_ok=True)
    body = markdown.strip("\n") + "\n"
    block = f"<!-- section: {section} -->\n{body}<!-- end: {section} -->\n"
    with _locked(path.parent):
        text = path.read_text(encoding="utf-8") if path.exists() else CLAIMS_HEADER
        esc = re.escape(section)
        own = re.search(rf"^<!-- section: {esc} -->\n.*?^<!-- end: {esc} -->\n?", text, re.M | re.S)
        if own:
            text = text[: own.start()] + block + text[own.end() :]
        else:
            later = [m for m in re.finditer(r"^<!-- section: (\S+) -->$", text, re.M) if m[1] > section]
            if later:
                at = later[0].start()
                text = text[:at] + block + "\n" + text[at:]
            else:
                text = text.rstrip("\n") + "\n\n" + block
        return write_text(text, path)
