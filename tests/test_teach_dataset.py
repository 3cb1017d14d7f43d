"""The answers of several sessions as one table: exported, described, read back, and read per person."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from hipref.envs.task import Clip
from hipref.experiments.domains import domain_spec
from hipref.teach.answers import agreement_across_people, krippendorff_alpha, per_participant, psychometric
from hipref.teach.config import TeachConfig
from hipref.teach.dataset import NAMES, export, main, read_sessions
from hipref.teach.preferences import ShownQuery, answer_record
from hipref.teach.session import SessionFile
from hipref.teachers.preference import PreferenceQuery, pair_labels

TRUTH = 0.7
ANSWERS = 1000
"""Answers per synthetic participant: the flip-rate estimates' standard error is then at most 0.015, and
0.05 is more than three of them."""


def synthetic_session(folder: Path, name: str, flip_rate: float, seed: int) -> Path:
    """A person of flip rate `flip_rate` answering `ANSWERS` uniform pairs of the wiping grid (none equally
    near the truth), written by the session's own writer."""
    config = TeachConfig(teacher="person", true_parameter=TRUTH, seed=seed, preference_queries=ANSWERS)
    session = SessionFile(folder / name, config.header(), fresh=True)
    rng = np.random.default_rng(seed)
    grid = domain_spec("wiping").candidates.values
    number = 0
    while number < ANSWERS:
        a, b = rng.choice(grid, size=2, replace=False)
        clean, tie = pair_labels(np.array([a]), np.array([b]), TRUTH)
        if tie[0]:
            continue
        preferred = 0 if clean[0] == 1 else 1
        if rng.random() < flip_rate:
            preferred = 1 - preferred
        order = tuple(int(i) for i in rng.permutation(2))
        clip = Clip(float(a), 200, 10, np.zeros(4))
        shown = ShownQuery(number, PreferenceQuery((float(a), float(b)), np.zeros(4)), clip, order, None)
        seconds = 2.0 + float(rng.exponential(3.0)) if number % 10 else 0.2
        session.append(answer_record(shown, shown.side_of(preferred), seconds, seed))
        number += 1
    return session.path


@pytest.fixture(scope="module")
def folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Two people of flip rates 0.1 and 0.3 (each line is written, not synced: durability is tested in
    test_teach_session.py)."""
    path = tmp_path_factory.mktemp("sessions")
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr("hipref.teach.session.os.fsync", lambda descriptor: None)
        synthetic_session(path, "person_wiping_seed1.jsonl", 0.1, 1)
        synthetic_session(path, "person_wiping_seed2.jsonl", 0.3, 2)
    return path


def test_export_recovers_each_persons_flip_rate(folder: Path, tmp_path: Path) -> None:
    table = export(folder, tmp_path)
    assert len(table) == 2 * ANSWERS and list(table.columns) == list(NAMES)
    assert set(table["teacher"]) == {"person"}
    people = per_participant(table).set_index("participant")
    for name, rate in (("person_wiping_seed1", 0.1), ("person_wiping_seed2", 0.3)):
        row = people.loc[name]
        assert abs(row["flip_rate_likelihood"] - rate) < 0.05, (name, row["flip_rate_likelihood"])
        assert abs(row["flip_rate_truth"] - rate) < 0.05, (name, row["flip_rate_truth"])
        assert row["agreement_low"] < row["agreement"] < row["agreement_high"]
        assert 0.02 < row["agreement_high"] - row["agreement_low"] < 0.08
        # Two answers to one pair agree with probability (1 - e)^2 + e^2.
        assert abs(row["repeated_consistency"] - ((1 - rate) ** 2 + rate**2)) < 0.06
        assert row["too_fast"] == ANSWERS // 10
    # The files are read back as written, by CSV and by Parquet.
    for read in (pd.read_csv(tmp_path / "answers.csv"), pd.read_parquet(tmp_path / "answers.parquet")):
        assert len(read) == len(table)
        np.testing.assert_allclose(read["seconds"], table["seconds"].to_numpy(float))
        assert list(read["answer"]) == list(table["answer"])


def test_psychometric_bins_hold_every_judged_answer(folder: Path) -> None:
    table = read_sessions(folder)
    curve = psychometric(table)
    judged = per_participant(table).set_index("session")["judged"]
    assert curve.groupby("session")["n"].sum().to_dict() == judged.to_dict()
    far = curve[curve["distance_low"] == 0.5]
    assert (far["p_correct"] > 0.6).all() and (far["low"] <= far["p_correct"]).all()


def test_data_card_lists_every_column(folder: Path, tmp_path: Path) -> None:
    table = export(folder, tmp_path)
    card = (tmp_path / "answers.md").read_text()
    rows = [line for line in card.splitlines() if line.startswith("| `")]
    assert [row.split("`")[1] for row in rows] == list(table.columns)
    # Five cells a row: no description breaks the markdown table.
    assert all(row.count("|") == 6 for row in rows)
    assert f"{len(table)} preference answers" in card


def test_krippendorff_alpha_matches_the_published_example() -> None:
    """Krippendorff (2011), "Computing Krippendorff's alpha-reliability": four coders, twelve units with
    missing values; nominal alpha 0.743."""
    coders = [
        [1, 2, 3, 3, 2, 1, 4, 1, 2, None, None, None],
        [1, 2, 3, 3, 2, 2, 4, 1, 2, 5, None, 3],
        [None, 3, 3, 3, 2, 3, 4, 2, 2, 5, 1, None],
        [1, 2, 3, 3, 2, 4, 4, 1, 2, 5, 1, None],
    ]
    units = [[v for v in unit if v is not None] for unit in zip(*coders, strict=True)]
    assert krippendorff_alpha(units) == pytest.approx(0.743, abs=5e-4)
    assert np.isnan(krippendorff_alpha([[1], [2]]))


def test_agreement_across_people_on_shared_pairs(folder: Path) -> None:
    table = read_sessions(folder)
    alpha, pairs, people = agreement_across_people(table)
    assert people == 2 and pairs > 100
    # Two people who are right 90% and 70% of the time agree on a pair with probability 0.66.
    assert 0.0 < alpha < 0.6
    same = table.copy()
    same["participant"], same["session"] = "copy", "copy.jsonl"
    assert agreement_across_people(pd.concat([table.iloc[:ANSWERS], same.iloc[:ANSWERS]]))[0] == 1.0


def test_malformed_line_is_refused_naming_file_and_line(folder: Path, tmp_path: Path) -> None:
    lines = (folder / "person_wiping_seed1.jsonl").read_text().splitlines()
    bad = tmp_path / "person_wiping_seed9.jsonl"
    bad.write_text("\n".join([*lines[:3], '{"kind": "preference", "answer": "le', *lines[3:5]]) + "\n")
    with pytest.raises(ValueError, match=rf"{bad.name}, line 4: not JSON"):
        read_sessions(tmp_path)
    record = json.loads(lines[2])
    record["label"] = -record["label"]
    bad.write_text("\n".join([lines[0], json.dumps(record)]) + "\n")
    with pytest.raises(ValueError, match=rf"{bad.name}, line 2: label .* contradicts answer"):
        read_sessions(tmp_path)
    bad.write_text(lines[1] + "\n")
    with pytest.raises(ValueError, match=rf"{bad.name}, line 1: not a session header"):
        read_sessions(tmp_path)
    bad.write_text("\n".join([*lines[:3], lines[3][:40]]))
    with pytest.raises(ValueError, match=rf"{bad.name}, line 4: not JSON .*cut off while it was written"):
        read_sessions(tmp_path)


def test_catch_trials_are_flagged_and_scored_apart(folder: Path, tmp_path: Path) -> None:
    lines = (folder / "person_wiping_seed2.jsonl").read_text().splitlines()[:41]
    records = [json.loads(line) for line in lines[1:]]
    for record in records[:20]:
        record["catch"] = True
    (tmp_path / "p.jsonl").write_text("\n".join([lines[0], *map(json.dumps, records)]) + "\n")
    table = read_sessions(tmp_path)
    assert table["catch_trial"].sum() == 20
    person = per_participant(table).iloc[0]
    assert person["catch_trials"] == 20
    assert person["catch_agreement"] == pytest.approx(table["agrees"][:20].mean())


def test_command_exports_and_refuses_missing_or_empty_folders(
    folder: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main([str(folder), str(tmp_path / "table")]) == 0
    assert f"{2 * ANSWERS} answers of 2 participants" in capsys.readouterr().out
    written = {p.name for p in (tmp_path / "table").iterdir()}
    assert written == {"answers.csv", "answers.parquet", "answers.md"}
    assert main([str(tmp_path / "absent"), str(tmp_path / "out")]) == 1
    assert "no sessions folder" in capsys.readouterr().err
    assert main([str(tmp_path), str(tmp_path / "out")]) == 1
    assert "holds no session files" in capsys.readouterr().err
    assert main([str(tmp_path)]) == 2
    assert not (tmp_path / "out").exists()
