"""Properties of the result writers: atomic, section-preserving, and strict about the tidy format."""

from __future__ import annotations

import os
from pathlib import Path

import pandas as pd
import pytest
from matplotlib.figure import Figure

from hipref import results
from hipref.results import (
    TIDY_COLUMNS,
    check_tidy,
    claims_table,
    results_dir,
    save_figure,
    tidy_rows,
    update_claims,
    write_csv,
    write_text,
)

REPO = Path(__file__).resolve().parent.parent


def tidy_frame() -> pd.DataFrame:
    return pd.DataFrame(
        {
            "domain": ["wiping", "pushing"],
            "method": ["pesi", "osi"],
            "noise": [0.2, 0.0],
            "seed": [0, 1],
            "episode": [3, 3],
            "metric": ["param_error", "success_rate"],
            "value": [0.012, 0.9],
        }
    )


def test_writers_leave_only_their_files(tmp_path: Path) -> None:
    fig = Figure(figsize=(2, 2))
    fig.add_subplot().plot([0, 1], [1, 0])
    write_csv(tidy_frame(), tmp_path / "data" / "01_x.csv")
    save_figure(fig, tmp_path / "figures" / "fig3.png")
    write_text("hello\n", tmp_path / "tables" / "note.md")

    written = sorted(p.relative_to(tmp_path).as_posix() for p in tmp_path.rglob("*") if p.is_file())
    assert written == ["data/01_x.csv", "figures/fig3.png", "tables/note.md"]
    assert pd.read_csv(tmp_path / "data" / "01_x.csv").equals(tidy_frame())
    assert (tmp_path / "figures" / "fig3.png").read_bytes().startswith(b"\x89PNG")
    assert (tmp_path / "tables" / "note.md").read_text() == "hello\n"


def test_same_figure_gives_same_bytes(tmp_path: Path) -> None:
    def draw() -> Figure:
        fig = Figure(figsize=(2, 2))
        fig.add_subplot().plot([0, 1, 2], [1, 0, 1])
        return fig

    assert (
        save_figure(draw(), tmp_path / "a.png").read_bytes()
        == save_figure(draw(), tmp_path / "b.png").read_bytes()
    )
    with pytest.raises(ValueError, match=r"\.png"):
        save_figure(draw(), tmp_path / "a.pdf")


def test_interrupted_write_keeps_the_old_file_and_no_temporary(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    target = tmp_path / "claims.md"
    target.write_text("old\n")

    def fail(*args: object) -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr(os, "replace", fail)
    with pytest.raises(KeyboardInterrupt):
        write_text("new\n", target)
    assert target.read_text() == "old\n"
    assert os.listdir(tmp_path) == ["claims.md"]


def test_update_claims_replaces_only_its_own_section(tmp_path: Path) -> None:
    path = tmp_path / "claims.md"
    update_claims("03_pushing", "push claims v1", path)
    update_claims("01_wiping", "wipe claims v1\n\nwith two paragraphs", path)
    update_claims("02_sysid", "sysid claims v1", path)
    text = path.read_text()
    assert text.startswith(results.CLAIMS_HEADER)
    names = [line.split()[2] for line in text.splitlines() if line.startswith("<!-- section:")]
    assert names == ["01_wiping", "02_sysid", "03_pushing"], "sections are kept sorted by name"

    update_claims("02_sysid", "sysid claims v2", path)
    updated = path.read_text()
    assert "sysid claims v2" in updated and "sysid claims v1" not in updated
    before, after = text.split("sysid claims v1")
    assert updated == before + "sysid claims v2" + after, "every other byte is unchanged"

    update_claims("02_sysid", "sysid claims v2", path)
    assert path.read_text() == updated, "updating with the same text changes nothing"


def test_update_claims_refuses_markers_and_odd_names(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="section name"):
        update_claims("bad name -->", "x", tmp_path / "claims.md")
    with pytest.raises(ValueError, match="markers"):
        update_claims("ok", "<!-- end: other -->", tmp_path / "claims.md")


def test_claims_table() -> None:
    table = claims_table(
        [
            ("PESI beats OSI under 20% noise", "error 1 cm vs 4 cm", "1.2 cm vs 3.9 cm", "yes"),
            ("Co-PESI needs no noise level", "a | b", "it does", "no"),
        ]
    )
    lines = table.splitlines()
    assert lines[0] == "| Claim | Paper says | Study measured | Holds |"
    assert lines[2].endswith("| yes |") and lines[3].endswith("| no |")
    assert r"a \| b" in lines[3], "a pipe inside a cell does not split it"
    with pytest.raises(ValueError, match="holds must be one of"):
        claims_table([("c", "p", "s", "maybe")])


def test_check_tidy() -> None:
    assert check_tidy(tidy_frame()) is not None
    with pytest.raises(ValueError, match="'seed'"):
        check_tidy(tidy_frame().drop(columns="seed"))
    with pytest.raises(ValueError, match="accuracy"):
        check_tidy(tidy_frame().assign(metric="accuracy"))
    with pytest.raises(ValueError, match="fraction"):
        check_tidy(tidy_frame().assign(noise=20.0))
    assert set(results.METRICS) >= {"param_error", "success_rate", "true_noise"}


def test_results_dir(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.delenv("HIPREF_RESULTS_DIR", raising=False)
    monkeypatch.chdir(tmp_path)
    assert results_dir() == REPO / "results", "independent of the working directory"
    monkeypatch.setenv("HIPREF_RESULTS_DIR", str(tmp_path / "elsewhere"))
    assert results_dir() == tmp_path / "elsewhere"
    update_claims("01_x", "claim", None)
    assert (tmp_path / "elsewhere" / "claims.md").is_file()


def test_tidy_rows_put_the_tidy_columns_first_then_the_others_in_the_order_given() -> None:
    rows = tidy_rows(
        [(0, "cells_wiped", 3.0, 12), (1, "cells_wiped", 5.0, 9)],
        ("episode", "metric", "value", "decisions"),
        domain="wiping",
        method="tabular_coach",
        noise=0.0,
        seed=4,
        ground_truth=0.7,
    )
    assert list(rows.columns) == [*TIDY_COLUMNS, "decisions", "ground_truth"]
    assert rows.episode.tolist() == [0, 1] and rows.seed.tolist() == [4, 4]
    with pytest.raises(ValueError, match="tidy column"):
        tidy_rows([(0, "cells_wiped", 3.0)], domain="wiping", method="m", noise=0.0)
