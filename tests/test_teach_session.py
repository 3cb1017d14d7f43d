"""A person's teaching session: answers stored before use, resumed after a crash, replayed exactly."""

from __future__ import annotations

import dataclasses
import errno
import itertools
import json
import os
import signal
import socket
import subprocess
import sys
import textwrap
import threading
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import torch

from hipref.experiments.domains import domain_spec
from hipref.learners import queries
from hipref.learners.answer_models import person_family
from hipref.learners.bayes import BayesConfig, BayesLearner
from hipref.learners.sysid import DESK_HEIGHT
from hipref.notebook import config_from_parameters
from hipref.teach import make_teach, open_session, participant
from hipref.teach import server as server_module
from hipref.teach.answers import learner_estimates, per_participant
from hipref.teach.app import (
    PREPARING,
    FeedbackApp,
    PreferenceApp,
    answer_feedback_as_scripted,
    answer_preferences_as_scripted,
)
from hipref.teach.config import TeachConfig
from hipref.teach.dataset import read_sessions
from hipref.teach.feedback import FeedbackTeaching
from hipref.teach.learner import warm
from hipref.teach.make_teach import main as participant_main
from hipref.teach.participant import ParticipantApp, practice_config
from hipref.teach.preferences import PreferenceTeaching, catch_pair
from hipref.teach.recorded import RecordedPreferenceTeacher, replay, summary
from hipref.teach.session import AnswerRefused, SessionFile, SessionLocked, SessionUnwritable

SMALL = dict(n_trajectories=8, pretrain_steps=20, preference_queries=6, feedback_steps=4, teacher="person")
"""A session on a small SI model, so the tests do not wait for Algorithm 4 at the study's scale."""


@pytest.fixture(scope="module")
def cache(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One cache for the module: the small SI model is pretrained once."""
    return tmp_path_factory.mktemp("cache")


@pytest.fixture
def results(tmp_path: Path, cache: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    monkeypatch.setenv("HIPREF_RESULTS_DIR", str(tmp_path / "results"))
    monkeypatch.setenv("HIPREF_CACHE_DIR", str(cache))
    return tmp_path / "results"


def free_port() -> int:
    """A port nothing listens on (that was free a moment ago)."""
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


def states_equal(a: torch.nn.Module, b: torch.nn.Module) -> bool:
    sa, sb = a.state_dict(), b.state_dict()
    return sa.keys() == sb.keys() and all(torch.equal(sa[k], sb[k]) for k in sa)


def lines(path: Path) -> list[dict]:
    return [json.loads(line) for line in path.read_text().splitlines()]


def test_an_answer_is_on_disk_before_the_learner_is_told(results, monkeypatch):
    config = TeachConfig(**SMALL, learner="pesi", query_rule="uniform")
    session = open_session(config)
    teaching = PreferenceTeaching(config, session, render=False)
    told = []
    original = teaching.learner.tell

    def tell(query, label):
        told.append(len(lines(session.path)) - 1)  # answers on disk when PESI hears this one
        original(query, label)

    monkeypatch.setattr(teaching.learner, "tell", tell)
    for answer in ("left", "right", "left"):
        teaching.answer(answer, 1.0)
    teaching.close()
    assert told == [1, 2, 3]


def test_with_chosen_queries_the_learner_kept_is_the_one_the_stored_answers_make(results, monkeypatch):
    # The next query is prepared for each possible answer on copies of the learner; the copy kept is the
    # one of the answer given, once that answer is on disk: it is the learner the file alone rebuilds.
    config = TeachConfig(**SMALL)
    session = open_session(config)
    teaching = PreferenceTeaching(config, session, render=False)
    for answer in ("left", "cant_tell", "right"):
        before = teaching.learner
        teaching.answer(answer, 1.0)
        records = session.of_kind("preference")
        assert records[-1]["answer"] == answer
        assert same_learner(teaching.learner, replay(config, records, "bayes"))
        assert teaching.learner is not before
    # A failed write keeps the learner and the query: nothing is adopted from an answer not on disk.
    shown, learner = teaching.current, teaching.learner

    def fail(record):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(session, "append", fail)
    with pytest.raises(OSError):
        teaching.answer("left", 1.0)
    assert teaching.current is shown and teaching.learner is learner
    teaching.close()


def test_cant_tell_is_stored_without_a_label_and_gives_pesi_none(results):
    config = TeachConfig(**SMALL, learner="pesi", query_rule="uniform")
    teaching = PreferenceTeaching(config, open_session(config), render=False)
    teaching.answer("cant_tell", 2.5)
    teaching.answer("left", 1.0)
    teaching.close()
    records = teaching.session.of_kind("preference")
    assert [r["answer"] for r in records] == ["cant_tell", "left"]
    assert records[0]["label"] is None and records[1]["label"] in (-1, 1)
    assert len(teaching.learner) == 1  # only the labelled answer is in PESI's buffer D


def test_a_bad_answer_is_refused_and_nothing_is_stored(results):
    config = TeachConfig(**SMALL)
    teaching = PreferenceTeaching(config, open_session(config), render=False)
    with pytest.raises(ValueError, match="answer must be one of"):
        teaching.answer("up", 1.0)
    feedback = FeedbackTeaching(config, teaching.session)
    with pytest.raises(ValueError, match="feedback must be one of"):
        feedback.answer(2, 1.0)
    teaching.close()
    assert lines(teaching.session.path)[1:] == []


def test_the_labels_follow_the_sides_the_candidates_were_shown_on(results):
    config = TeachConfig(**SMALL)
    teaching = PreferenceTeaching(config, open_session(config), render=False)
    sides = set()
    while (shown := teaching.current) is not None:
        sides.add(shown.order)
        # Pressing the side of candidate 0 is y = 1 (Eq. 2), whichever side it was shown on.
        assert shown.label(shown.side_of(0)) == 1 and shown.label(shown.side_of(1)) == -1
        teaching.answer(shown.side_of(1), 0.5)
    teaching.close()
    assert sides == {(0, 1), (1, 0)}  # both placements occur: the sides are drawn, not fixed


def same_learner(a, b) -> bool:
    """Two learners in the same state: PESI's SI weights, or the Bayesian learner's posterior."""
    if isinstance(a, BayesLearner):
        return np.array_equal(a.posterior.log_likelihood, b.posterior.log_likelihood)
    return states_equal(a.model, b.model)


@pytest.mark.parametrize(
    ("learner", "rule"), [("pesi", "uniform"), ("bayes", "information_gain"), ("pesi", "information_gain")]
)
def test_replaying_a_session_rebuilds_the_live_learner_exactly(results, learner, rule):
    config = TeachConfig(**SMALL, learner=learner, query_rule=rule)
    session = open_session(config)
    preferences = PreferenceApp(PreferenceTeaching(config, session, render=False))
    answer_preferences_as_scripted(preferences, noise=0.3, seed=1)
    preferences.teaching.close()
    records = session.of_kind("preference")
    assert len(records) == config.preference_queries
    replayed = replay(config, records, learner)
    assert same_learner(replayed, preferences.teaching.learner)
    # A recorded teacher refuses a query the person was not shown.
    teacher = RecordedPreferenceTeacher(records)
    with pytest.raises(ValueError, match="was shown"):
        teacher.answer(_other_query(records[0]))
    facts = summary(session, config)
    assert facts["answers"] == config.preference_queries
    assert 0.0 <= facts["agreement_with_truth"] <= 1.0
    assert {"pesi_error", "co_pesi_estimated_error", "bayes_error", "osi_error"} <= facts.keys()
    # The dataset of answers reads the same file as the session does.
    person = per_participant(read_sessions(session.path.parent)).iloc[0]
    assert person["agreement"] == pytest.approx(facts["agreement_with_truth"], nan_ok=True)
    errors = learner_estimates(session.path.parent).set_index("method")["error"]
    for method in ("osi", "pesi", "co_pesi_estimated", "bayes"):
        assert errors[method] == pytest.approx(facts[f"{method}_error"])


def _other_query(record: dict):
    from hipref.teachers.preference import PreferenceQuery

    a, b = record["candidates"]
    return PreferenceQuery((b, a), np.array(record["clip"]["tau"]))


CRASHING_SESSION = textwrap.dedent(
    """
    import os, signal, sys
    from hipref.teach import open_session
    from hipref.teach.config import TeachConfig
    from hipref.teach.feedback import FeedbackTeaching
    from hipref.teach.preferences import PreferenceTeaching
    config = TeachConfig(**{small})
    session = open_session(config)
    preferences = PreferenceTeaching(config, session, render=False)
    for answer in ("left", "cant_tell", "right"):
        preferences.answer(answer, 1.0)
    feedback = FeedbackTeaching(config, session)
    feedback.answer(1, 1.0)
    feedback.answer(-1, 1.0)
    os.kill(os.getpid(), signal.SIGKILL)  # the kernel dies with the next query being prepared
    """
)


@pytest.mark.slow
def test_a_killed_session_resumes_where_it_stopped(results, tmp_path):
    script = CRASHING_SESSION.format(small=SMALL)
    command = [sys.executable, "-c", script]
    died = subprocess.run(command, env=os.environ.copy(), capture_output=True, timeout=600)
    assert died.returncode == -signal.SIGKILL, died.stderr.decode()[-2000:]
    config = TeachConfig(**SMALL)
    session = open_session(config)  # a person's session resumes
    assert [r["answer"] for r in session.of_kind("preference")] == ["left", "cant_tell", "right"]
    resumed = PreferenceTeaching(config, session, render=False)
    resumed_feedback = FeedbackTeaching(config, session)
    # The same session answered straight through, without the crash.
    straight = SessionFile(tmp_path / "straight.jsonl", config.header())
    live = PreferenceTeaching(config, straight, render=False)
    for answer in ("left", "cant_tell", "right"):
        live.answer(answer, 1.0)
    live_feedback = FeedbackTeaching(config, straight)
    live_feedback.answer(1, 1.0)
    live_feedback.answer(-1, 1.0)
    assert same_learner(resumed.learner, live.learner)
    assert resumed.current.query.candidates == live.current.query.candidates  # the next query is the same
    np.testing.assert_array_equal(resumed.current.query.features, live.current.query.features)
    assert resumed_feedback.state == live_feedback.state
    assert resumed_feedback.proposed == live_feedback.proposed
    np.testing.assert_array_equal(resumed_feedback.coach.theta, live_feedback.coach.theta)
    for teaching in (resumed, live):
        teaching.close()


def test_a_torn_last_line_is_dropped_with_a_warning(tmp_path):
    path = tmp_path / "s.jsonl"
    session = SessionFile(path, {"seed": 0})
    session.append({"kind": "feedback", "step": 0})
    with path.open("ab") as file:
        file.write(b'{"kind": "feedback", "st')  # the kernel died while writing
    with pytest.warns(UserWarning, match="cut off"):
        again = SessionFile(path, {"seed": 0})
    assert again.records == [{"kind": "feedback", "step": 0}]
    again.append({"kind": "feedback", "step": 1})
    assert [r.get("step") for r in lines(path)[1:]] == [0, 1]


def test_another_sessions_file_is_refused(tmp_path):
    path = tmp_path / "s.jsonl"
    SessionFile(path, {"seed": 0, "domain": "wiping"})
    with pytest.raises(ValueError, match="fields seed differ"):
        SessionFile(path, {"seed": 1, "domain": "wiping"})
    assert SessionFile(path, {"seed": 1, "domain": "wiping"}, fresh=True).records == []


def test_the_widgets_answer_by_button_and_by_key(results):
    config = TeachConfig(**SMALL)
    session = open_session(config)
    preferences = PreferenceApp(PreferenceTeaching(config, session, render=False), reveal_truth=True)
    preferences.settle = 0.0
    preferences.wait_ready()
    preferences.buttons["left"].click()
    preferences._on_key({"type": "keydown", "key": "ArrowRight"})
    preferences._on_key({"type": "keydown", "key": "s"})
    preferences._on_key({"type": "keydown", "key": "q"})  # not an answer key: ignored
    assert [r["answer"] for r in session.of_kind("preference")] == ["left", "right", "cant_tell"]
    assert preferences.progress.value == 3 and "error" in preferences.status.value
    # The widget says whether the keys answer: ipyevents marks it `ipyevents-watched` while it has the focus.
    hint = preferences.keys_hint.value
    assert ".ipyevents-watched .hipref-keys-on{display:inline}" in hint and "keys off: point at" in hint
    feedback = FeedbackApp(FeedbackTeaching(config, session))
    feedback.settle = 0.0
    feedback.wait_ready()
    feedback.buttons[1].click()
    feedback._on_key({"type": "keydown", "key": "-"})
    feedback._on_key({"type": "keydown", "key": "0"})
    assert [r["feedback"] for r in session.of_kind("feedback")] == [1, -1, 0]
    answer_feedback_as_scripted(feedback)
    assert feedback.teaching.done and all(b.disabled for b in feedback.buttons.values())
    assert "<svg" in feedback.grid.value
    preferences.teaching.close()


def test_the_scripted_stand_in_records_no_wall_clock_time(results, monkeypatch):
    # It answers the moment a question is shown, so that its session file is the same bytes on every run;
    # here every answer would otherwise take a second or more.
    monkeypatch.setattr("hipref.teach.app.time", SimpleNamespace(perf_counter=itertools.count().__next__))
    config = TeachConfig(**{**SMALL, "teacher": "scripted", "preference_queries": 2})
    session = open_session(config)
    preferences = PreferenceApp(PreferenceTeaching(config, session, render=False))
    answer_preferences_as_scripted(preferences, noise=0.2, seed=0)
    preferences.teaching.close()
    answer_feedback_as_scripted(FeedbackApp(FeedbackTeaching(config, session)))
    assert len(session.records) == 2 + 4
    assert {record["seconds"] for record in session.records} == {0.0}


def test_config_refuses_bad_values():
    with pytest.raises(ValueError, match="teacher"):
        TeachConfig(teacher="robot")
    with pytest.raises(ValueError, match="true_parameter"):
        TeachConfig(true_parameter=1.5)
    with pytest.raises(ValueError, match="session must be a file name"):
        TeachConfig(session="../elsewhere.jsonl")


def test_nothing_is_prepared_once_every_query_is_answered(results):
    config = TeachConfig(**{**SMALL, "preference_queries": 2})
    teaching = PreferenceTeaching(config, open_session(config), render=False)
    teaching.answer("left", 1.0)
    teaching.answer("right", 1.0)
    assert teaching.current is None and not teaching._next  # no query beyond the planned ones
    resumed = PreferenceTeaching(config, teaching.session, render=False)
    assert resumed.current is None and not resumed._next
    for session in (teaching, resumed):
        session.close()


def test_before_and_after_executes_the_task_with_both_estimates(results, monkeypatch):
    from hipref.teach.outcome import before_and_after

    config = TeachConfig(**SMALL, true_parameter=0.62)
    teaching = PreferenceTeaching(config, open_session(config), render=False)
    # The session's physics is the thread's that prepares the next query; the outcome, executed while it
    # does, must not step it too (two threads on one MjData corrupt both the strokes and the next slice).
    executing = set()
    rollout = teaching._task.rollout

    def recorded(*args, **kwargs):
        executing.add(threading.current_thread().name)
        return rollout(*args, **kwargs)

    monkeypatch.setattr(teaching._task, "rollout", recorded)
    for answer in ("left", "right"):
        teaching.answer(answer, 1.0)
    outcome = before_and_after(teaching, attempts=2)
    assert outcome["estimate_before"] == teaching.initial_estimate == 0.7  # the prior's median: nothing heard
    assert outcome["estimate_after"] == teaching.estimate()
    assert outcome["error_before"] == pytest.approx(abs(0.7 - 0.62))
    assert {outcome["success_before"], outcome["success_after"]} <= {0.0, 0.5, 1.0}
    teaching.close()
    assert executing and all(name.startswith("hipref-next-query") for name in executing)


def test_every_answer_names_its_query_and_a_second_answer_to_one_is_refused(results, tmp_path):
    path = tmp_path / "s.jsonl"
    session = SessionFile(path, {"seed": 0})
    session.append({"kind": "preference", "query": 0})
    with pytest.raises(AnswerRefused, match="query 0 already has an answer"):
        session.append({"kind": "preference", "query": 0})
    with pytest.raises(AnswerRefused, match="the next unanswered query is 1"):
        session.append({"kind": "preference", "query": 2})
    session.append({"kind": "feedback", "step": 0})  # each kind numbers its own queries
    assert [(r["kind"], r.get("query", r.get("step"))) for r in lines(path)[1:]] == [
        ("preference", 0),
        ("feedback", 0),
    ]
    session.close()
    # A file two writers spoiled (two answers to one query) is refused with its line named.
    with path.open("a") as file:
        file.write(json.dumps({"kind": "preference", "query": 0}) + "\n")
    with pytest.raises(ValueError, match="line 4: preference query 0 already has an answer"):
        SessionFile(path, {"seed": 0})
    # Two live sessions of one file in one kernel: the answer of the one left behind is refused.
    config = TeachConfig(**SMALL)
    session = open_session(config)
    first = PreferenceTeaching(config, session, render=False)
    second = PreferenceTeaching(config, session, render=False)
    first.answer("left", 1.0)
    with pytest.raises(AnswerRefused, match="query 0 already has an answer"):
        second.answer("right", 1.0)
    assert [r["query"] for r in lines(session.path)[1:]] == [0]
    for teaching in (first, second):
        teaching.close()


HOLDER = textwrap.dedent(
    """
    import sys, time
    from hipref.teach.session import AnswerRefused, SessionFile, SessionLocked, SessionUnwritable
    session = SessionFile(sys.argv[1], {{"seed": 0}})
    print("open", flush=True)
    time.sleep(60)
    """
)


@pytest.mark.slow
def test_a_second_writer_of_a_session_file_is_refused_naming_the_first(tmp_path):
    path = tmp_path / "s.jsonl"
    holder = subprocess.Popen(
        [sys.executable, "-c", HOLDER.format(), str(path)], stdout=subprocess.PIPE, text=True
    )
    try:
        assert holder.stdout.readline().strip() == "open"
        with pytest.raises(SessionLocked, match=f"open in another live session \\(pid {holder.pid} on host "):
            SessionFile(path, {"seed": 0})
    finally:
        holder.kill()
        holder.wait()
    # Its process gone, the lock goes with it.
    session = SessionFile(path, {"seed": 0})
    session.append({"kind": "feedback", "step": 0})
    # In one process the newer session of a file takes it over; the older one writes no more.
    newer = SessionFile(path, {"seed": 0})
    with pytest.raises(SessionLocked, match="a newer session of this file was opened"):
        session.append({"kind": "feedback", "step": 1})
    newer.append({"kind": "feedback", "step": 1})
    assert [r["step"] for r in lines(path)[1:]] == [0, 1]


def test_a_failed_write_is_shown_in_the_widget_and_raised_by_the_stand_in(results, monkeypatch):
    config = TeachConfig(**SMALL)
    session = open_session(config)
    app = PreferenceApp(PreferenceTeaching(config, session, render=False))
    app.settle = 0.0
    assert app.wait_ready(timeout=5)
    original = session.append

    def full(record):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(session, "append", full)
    shown = app.teaching.current
    app.buttons["left"].click()
    assert "not saved" in app.message.value and "No space left" in app.message.value
    assert not any(b.disabled for b in app.buttons.values())  # live for another try
    assert app.teaching.current is shown and lines(session.path)[1:] == []
    monkeypatch.setattr(session, "append", original)
    app.buttons["left"].click()  # the retry is recorded, the message gone
    assert [r["answer"] for r in lines(session.path)[1:]] == ["left"] and app.message.value == ""
    monkeypatch.setattr(session, "append", full)
    with pytest.raises(OSError, match="No space left"):  # the stand-in stops rather than pressing forever
        answer_preferences_as_scripted(app, noise=0.0, seed=0)
    app.teaching.close()


@pytest.mark.parametrize("rule", ["uniform", "information_gain"])
def test_a_person_who_cannot_tell_pair_after_pair_goes_on_to_the_end(results, rule):
    config = TeachConfig(**{**SMALL, "query_rule": rule})
    app = PreferenceApp(PreferenceTeaching(config, open_session(config), render=False))
    app.settle = 0.0
    for _ in range(config.preference_queries):
        assert app.wait_ready(timeout=60)
        app.buttons["cant_tell"].click()
        assert app.error is None, app.message.value
    assert [r["answer"] for r in lines(app.teaching.session.path)[1:]] == ["cant_tell"] * 6
    assert app.teaching.done and np.isfinite(app.teaching.estimate())
    app.teaching.close()


def test_a_learner_that_fails_after_the_answer_is_saved_says_so_rather_than_freeze(results, monkeypatch):
    def broken(*args, **kwargs):
        raise ValueError("the learner broke")

    # Told in the background, where the next query is prepared: the failure meets the answer that needs it.
    monkeypatch.setattr("hipref.teach.preferences.told", broken)
    config = TeachConfig(**SMALL)
    app = PreferenceApp(PreferenceTeaching(config, open_session(config), render=False))
    app.settle = 0.0
    assert app.wait_ready(timeout=5)
    app.buttons["left"].click()  # the click's handler raises into the kernel's log, not here
    assert "Something went wrong" in app.message.value and "the learner broke" in app.message.value
    assert "saved" in app.message.value and all(b.disabled for b in app.buttons.values())
    assert [r["answer"] for r in lines(app.teaching.session.path)[1:]] == ["left"]
    app.teaching.close()


def test_an_unwritable_session_file_is_refused_before_the_first_query(results, monkeypatch):
    config = TeachConfig(**SMALL)
    open_session(config).close()
    real_open = os.open

    def read_only(path, flags, *args):
        if str(path).endswith(".jsonl") and flags & os.O_WRONLY:
            raise PermissionError(errno.EACCES, "Permission denied")
        return real_open(path, flags, *args)

    monkeypatch.setattr(os, "open", read_only)
    refused = "cannot be written \\(Permission denied\\): no answer could be saved"
    with pytest.raises(SessionUnwritable, match=refused):
        open_session(config)


def test_presses_while_a_pair_is_prepared_or_settling_are_ignored(results, monkeypatch):
    config = TeachConfig(**SMALL)
    session = open_session(config)
    app = PreferenceApp(PreferenceTeaching(config, session, render=False))
    assert all(b.disabled for b in app.buttons.values())  # the first pair settles too
    app.press("left")
    assert app.ignored == 1 and lines(session.path)[1:] == []
    assert app.wait_ready(timeout=5)
    seen = []
    answer = app.teaching.answer

    def watched(value, seconds):
        seen.append([(b.disabled, b.description) for b in app.buttons.values()])
        answer(value, seconds)

    monkeypatch.setattr(app.teaching, "answer", watched)
    app.buttons["left"].click()  # a double click: the second press comes while the next pair settles
    app.buttons["left"].click()
    app._on_key({"type": "keydown", "key": "ArrowRight"})  # and a key right after
    assert seen == [[(True, PREPARING)] * 3]  # while it was stored and the next pair prepared
    assert [r["query"] for r in lines(session.path)[1:]] == [0] and app.ignored == 3
    assert all(b.disabled and b.description == PREPARING for b in app.buttons.values())
    assert app.wait_ready(timeout=5)
    assert not any(b.disabled for b in app.buttons.values())
    app._on_key({"type": "keydown", "key": "ArrowRight"})
    assert [r["answer"] for r in lines(session.path)[1:]] == ["left", "right"]
    app.teaching.close()


def test_a_finished_session_reopens_to_its_summary(results):
    config = TeachConfig(**{**SMALL, "preference_queries": 2, "feedback_steps": 2})
    session = open_session(config)
    preferences = PreferenceApp(PreferenceTeaching(config, session, render=False))
    answer_preferences_as_scripted(preferences, noise=0.0, seed=0)
    answer_feedback_as_scripted(FeedbackApp(FeedbackTeaching(config, session)))
    preferences.teaching.close()
    reopened = open_session(config)
    preferences = PreferenceApp(PreferenceTeaching(config, reopened, render=False))
    feedback = FeedbackApp(FeedbackTeaching(config, reopened))
    assert "All 2 preference queries answered" in preferences.heading.value
    assert "Feedback episode over" in feedback.heading.value
    assert feedback.teaching.steps == 2 and feedback.teaching.proposed is None
    for app in (preferences, feedback):
        assert all(b.disabled for b in app.buttons.values())
        app.press(app.KEYS[next(iter(app.KEYS))])
        assert app.ignored == 1
    assert summary(reopened, config)["answers"] == 2
    assert len(lines(reopened.path)) == 1 + 2 + 2
    preferences.teaching.close()


def test_catch_trials_are_flagged_and_not_told_to_the_learner(results):
    config = TeachConfig(**{**SMALL, "preference_queries": 4, "catch_every": 2})
    session = open_session(config)
    app = PreferenceApp(PreferenceTeaching(config, session, render=False))
    answer_preferences_as_scripted(app, noise=0.0, seed=0)
    app.teaching.close()
    records = lines(session.path)[1:]
    assert [r["catch"] for r in records] == [False, True, False, True]
    near, far = catch_pair(DESK_HEIGHT, config.true_parameter)
    assert (near, far) == (0.8, 0.5)  # the truth against the range's end farthest from it (0.9 on a tie)
    assert all(r["candidates"] == [near, far] for r in records if r["catch"])
    assert all(r["label"] == 1 for r in records if r["catch"])  # the stand-in without flips: the truth
    # The learner heard only the learner's queries: the file without its catch trials rebuilds it.
    assert same_learner(app.teaching.learner, replay(config, [r for r in records if not r["catch"]], "bayes"))
    resumed = PreferenceTeaching(config, open_session(config), render=False)
    assert same_learner(resumed.learner, app.teaching.learner)
    resumed.close()
    table = read_sessions(session.path.parent)
    assert table["catch_trial"].tolist() == [False, True, False, True]


def test_a_participant_is_led_through_practice_conditions_and_a_closing_screen(results):
    config = TeachConfig(
        **{**SMALL, "preference_queries": 2, "catch_every": 2},
        participant="P1",
        conditions=("uniform", "information_gain"),
    )
    app = ParticipantApp(config, render=False)
    text = app.widget.children[0].value
    assert "height of the desk" in text and "4 pairs in 2 parts. Some pairs are easy on purpose." in text
    # No catch trial among the queries (none asked for, or fewer queries than catch_every): none promised.
    for fewer in ({"catch_every": 0}, {"catch_every": 3}):
        plain = ParticipantApp(dataclasses.replace(config, participant="P1b", **fewer), render=False)
        assert "easy on purpose" not in plain.widget.children[0].value
    app.widget.children[1].click()  # start the practice
    shown = app.practice.teaching.current
    assert shown.catch and shown.query.candidates == (0.8, 0.5)
    app.practice.press_as_scripted(shown.side_of(1))  # the wrong clip
    feedback = app.widget.children[0].value
    # Which clip was right and which way the other erred, but no value: the participant judges the motion.
    assert "Not quite" in feedback and "the other with a guess too low." in feedback
    assert "0.8" not in feedback and "0.5" not in feedback
    app.widget.children[1].click()
    for part in range(2):
        assert f"Part {part + 1} of 2" in app.widget.children[0].value
        condition = app.apps[part]
        assert condition.status.value == "answered 0 of 2"  # nor the learner's running estimate
        while (query := condition.teaching.current) is not None:
            condition.press_as_scripted(query.side_of(0))
        if part == 0:
            assert "Part 1 of 2 done" in app.widget.children[0].value
            app.widget.children[1].click()
    assert "Thank you" in app.widget.children[0].value
    assert "All 4 answers are saved" in app.widget.children[0].value
    sessions = results / "sessions"
    for rule in config.conditions:
        header, *answers = lines(sessions / f"participant_P1_{rule}.jsonl")
        assert header["participant"] == "P1" and header["conditions"] == ["uniform", "information_gain"]
        assert header["query_rule"] == rule and [a["catch"] for a in answers] == [False, True]
    table = read_sessions(sessions)  # the practice pair is not in the dataset of answers
    assert set(table["participant"]) == {"P1"} and len(table) == 4
    assert set(table["teacher"]) == {"person"}  # a person's answers, which notebook 09's outputs leave out
    assert lines(sessions / "practice" / "participant_P1_practice.jsonl")[1]["answer"] == shown.side_of(1)
    # Coming back after the last answer: the closing screen, not a welcome back to nothing left.
    again = ParticipantApp(config, render=False)
    assert len(again.widget.children) == 1 and "All 4 answers are saved" in again.widget.children[0].value
    assert "Welcome back" not in again.widget.children[0].value
    again._start_condition(0)  # the same when the last part is finished while a page is open
    assert "Thank you" in again.widget.children[0].value


def test_a_participant_who_comes_back_skips_the_practice_and_keeps_its_answer(results):
    config = TeachConfig(**{**SMALL, "preference_queries": 1, "catch_every": 2}, participant="P2")
    first = ParticipantApp(config, render=False)
    first.widget.children[1].click()
    assert first.practice is not None and first.practice.teaching.current is not None
    first.practice.press_as_scripted("left")
    practice = results / "sessions" / "practice" / "participant_P2_practice.jsonl"
    kept = practice.read_text()
    # The window closed after the practice; the participant comes back: straight to the first part.
    again = ParticipantApp(config, render=False)
    assert (
        "Welcome back" in again.widget.children[0].value and "practice" not in again.widget.children[0].value
    )
    assert again.widget.children[1].description == "Continue"
    again.widget.children[1].click()
    assert "Part 1 of 1" in again.widget.children[0].value and again.practice is None
    assert practice.read_text() == kept
    again.apps[0].teaching.close()


def test_a_part_met_again_by_refused_presses_is_counted_once_on_the_closing_screen(results, monkeypatch):
    config = TeachConfig(
        **{**SMALL, "preference_queries": 1, "catch_every": 2},
        participant="P11",
        conditions=("uniform", "information_gain"),
    )
    first = ParticipantApp(config, render=False)
    first.widget.children[1].click()
    first.practice.press_as_scripted("left")
    first.widget.children[1].click()  # part 1
    first.apps[0].press_as_scripted("left")  # part 1 done; the window closes at the break
    # A second window: part 2 is held elsewhere (an earlier window not yet shut down) for two presses.
    opened = participant.SessionFile
    held = iter([True, True])

    def part_two_held(path, header, **kwargs):
        if "information_gain" in Path(path).name and next(held, False):
            raise SessionLocked(f"{Path(path).name} is open in another live session (pid 1 on host h)")
        return opened(path, header, **kwargs)

    monkeypatch.setattr(participant, "SessionFile", part_two_held)
    again = ParticipantApp(config, render=False)
    button, status = again.widget.children[1:]
    button.click()
    button.click()  # refused twice, each time passing the finished part 1 on the way
    assert "still open in an earlier window" in status.value
    button.click()
    assert "Part 2 of 2" in again.widget.children[0].value
    again.apps[-1].press_as_scripted("left")
    assert "All 2 answers are saved" in again.widget.children[0].value


def test_a_start_button_acts_once_and_says_why_when_the_session_is_held(results, monkeypatch):
    config = TeachConfig(**{**SMALL, "preference_queries": 1, "catch_every": 2}, participant="P3")
    app = ParticipantApp(config, render=False)
    held = SessionLocked("participant_P3_practice.jsonl is open in another live session (pid 1 on host h)")
    calls = []

    def start() -> None:
        calls.append(len(calls))
        if len(calls) == 1:
            raise held

    monkeypatch.setattr(app, "_start_practice", start)
    app._screen("instructions", "Start the practice pair", app._start_practice)
    button, status = app.widget.children[1:]
    button.click()  # the session is held by a window not yet closed: said, and the button works again
    assert "still open in an earlier window" in status.value and "within 90 seconds" in status.value
    assert not button.disabled
    button.click()
    button.click()  # a second press while the next screen is prepared: ignored
    assert calls == [0, 1] and button.disabled


def test_a_page_opened_while_the_practice_is_open_elsewhere_says_so_without_a_traceback(results, monkeypatch):
    config = TeachConfig(**{**SMALL, "preference_queries": 1, "catch_every": 2}, participant="P10")

    def held(path: Path, _: TeachConfig) -> bool:  # the earlier window's kernel still holds the practice
        raise SessionLocked(f"{path.name} is open in another live session (pid 1 on host h)")

    monkeypatch.setattr(participant, "_practised", held)
    app = ParticipantApp(config, render=False)
    text, button, status = app.widget.children
    assert "open in another window or tab" in text.value and "Welcome back" not in text.value
    assert button.description == "Continue"
    button.click()
    assert "still open in an earlier window" in status.value and not button.disabled


def test_a_start_button_that_fails_otherwise_says_so_and_can_be_pressed_again(results):
    config = TeachConfig(**{**SMALL, "preference_queries": 1, "catch_every": 2}, participant="P5")
    app = ParticipantApp(config, render=False)

    def broken() -> None:
        raise RuntimeError("no clips")

    app._screen("instructions", "Start", broken)
    button, status = app.widget.children[1:]
    button.click()  # ipywidgets shows the error's traceback, for the experimenter, and goes on
    assert "please tell the experimenter" in status.value and "no clips" in status.value
    assert not button.disabled


def running(pid: int) -> bool:
    """Whether process `pid` exists and has not ended (a zombie, ended but not yet reaped, has)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except FileNotFoundError:
        return False


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the parent-death signal is Linux's")
def test_the_server_does_not_outlive_a_killed_make_teach(tmp_path):
    # `serve` as `make teach` runs it, with a stand-in server that writes its pid and sleeps; the parent is
    # then killed outright (no handler runs), and the server must still end.
    pid_file = tmp_path / "server.pid"
    server = f"import os, time; open({str(pid_file)!r}, 'w').write(str(os.getpid())); time.sleep(120)"
    parent = subprocess.Popen(
        [
            sys.executable,
            "-c",
            f"from hipref.teach.server import serve; serve([{sys.executable!r}, '-c', {server!r}], 9, '')",
        ]
    )
    try:
        for _ in range(600):
            if pid_file.exists() and pid_file.read_text():
                break
            threading.Event().wait(0.05)
        server_pid = int(pid_file.read_text())
    finally:
        parent.kill()
        parent.wait()
    for _ in range(200):
        if not running(server_pid):
            break
        threading.Event().wait(0.05)
    else:
        os.kill(server_pid, signal.SIGKILL)
        pytest.fail("the server outlived its killed parent by 10 s")


def test_make_teach_gives_the_address_once_the_server_listens_and_not_if_it_never_does(monkeypatch, capsys):
    listening = iter([False, False, True])
    monkeypatch.setattr(server_module, "port_in_use", lambda port: next(listening))
    server_module.serve([sys.executable, "-c", "import time; time.sleep(2)"], 8866, "ready at 8866")
    assert capsys.readouterr().out == "ready at 8866\n" and next(listening, None) is None
    monkeypatch.setattr(server_module, "port_in_use", lambda port: False)
    server_module.serve([sys.executable, "-c", "pass"], 8866, "ready at 8866")  # ended before listening
    assert capsys.readouterr().out == ""
    with pytest.raises(SystemExit) as stopped:  # failed by itself: said in one line, not a silent success
        server_module.serve([sys.executable, "-c", "raise SystemExit(3)"], 8866, "ready at 8866")
    assert stopped.value.code == 1
    assert capsys.readouterr().err == "make teach: the server stopped with exit status 3 (its log is above)\n"


def _make_teach(env: dict[str, str], *settings: str) -> subprocess.CompletedProcess[str]:
    """`make teach` with `settings` on its command line, without its install step (`-o install`), in the
    checkout, with `env` but an outer make's flags (a `make -j2` or `make pytest X=...` around the tests)."""
    env = {k: v for k, v in env.items() if k not in ("MAKEFLAGS", "MFLAGS", "MAKELEVEL", "MAKEOVERRIDES")}
    command = ["make", "-s", "-o", "install", "teach", *settings]
    root = Path(__file__).resolve().parents[1]
    return subprocess.run(command, cwd=root, env=env, capture_output=True, text=True, timeout=60)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the parent-death signal is Linux's")
@pytest.mark.parametrize("kill", [signal.SIGTERM, signal.SIGKILL], ids=["SIGTERM", "SIGKILL"])
def test_a_kill_of_make_itself_stops_the_participants_server(tmp_path, kill):
    # A researcher who kills `make teach`'s make (not the process group, as Ctrl-C does) must not leave
    # the participant's server running on the port.
    outer = ("MAKEFLAGS", "MFLAGS", "MAKELEVEL", "MAKEOVERRIDES")
    env = {k: v for k, v in os.environ.items() if k not in outer}
    env |= {"HIPREF_RESULTS_DIR": str(tmp_path / "results"), "HIPREF_CACHE_DIR": str(tmp_path / "cache")}
    port = free_port()
    root = Path(__file__).resolve().parents[1]
    command = ["make", "-s", "-o", "install", "teach", "PARTICIPANT=K1", f"PORT={port}"]
    pipe = subprocess.PIPE
    make = subprocess.Popen(command, cwd=root, env=env, stdout=pipe, stderr=pipe, text=True)
    try:
        assert make.stdout is not None
        for line in make.stdout:  # until the address, printed once the server listens
            if f"http://127.0.0.1:{port}/" in line and line.startswith("participant K1"):
                break
        else:
            said = make.stderr.read() if make.stderr else ""
            if "cannot be rendered" in said:
                pytest.skip(f"no GL here: {said.strip()}")
            pytest.fail(f"make teach ended before serving: {said}")
        make.send_signal(kill)
        make.wait(timeout=20)
        for _ in range(200):
            if not server_module.port_in_use(port):
                break
            threading.Event().wait(0.1)
        else:
            pytest.fail(f"the server still listens on {port} 20 s after make was killed ({kill.name})")
    finally:
        if make.poll() is None:
            make.kill()


def test_make_teach_refuses_a_setting_it_does_not_know():
    done = _make_teach(dict(os.environ), "PARTICIPANT=P1", "QUERY=4", "DOMIAN=pushing")
    assert (done.returncode, done.stdout) == (2, "")
    assert done.stderr.splitlines()[0] == (
        "make teach: unknown setting(s) DOMIAN QUERY; make teach takes PARTICIPANT CONDITIONS CATCH_EVERY "
        "PORT DOMAIN QUERIES TRUE_PARAMETER PYTHON MUJOCO_GL"
    )


def test_make_teach_says_a_participant_set_in_the_shell_is_not_read(tmp_path):
    # make's own PARTICIPANT (empty) wins over the shell's; the command says so instead of only "missing",
    # and prints the shell's value as it is: neither make nor the shell runs it.
    ran = tmp_path / "ran"
    given = f"P01; touch {ran}; $(shell touch {ran}) a\\cb"
    env = {**os.environ, "PARTICIPANT": given}
    done = _make_teach(env)
    assert (done.returncode, done.stdout) == (2, "")
    assert done.stderr.splitlines()[:2] == [
        f"make teach: PARTICIPANT={given} is set in the shell, which make teach does not read",
        "make teach PARTICIPANT=<id>: the participant id is missing",
    ]
    env.pop("PARTICIPANT")
    done = _make_teach(env)
    assert done.returncode == 2
    assert done.stderr.splitlines()[0] == "make teach PARTICIPANT=<id>: the participant id is missing"
    # Given on make's command line, the id reaches the command as typed, which refuses it.
    done = _make_teach(env, f"PARTICIPANT=$(shell touch {ran})")
    assert done.returncode == 2
    assert f"got '$(shell touch {ran})'" in done.stderr
    assert not ran.exists()


def test_make_teach_refuses_a_bad_id_a_port_in_use_or_out_of_range_in_one_line(capsys):
    with pytest.raises(SystemExit) as stopped:
        participant_main(["x/y"])
    assert stopped.value.code == 2
    said = capsys.readouterr().err
    assert said.startswith("make teach: PARTICIPANT (participant) must be 1-40 letters, digits, - or _")
    assert said.count("\n") == 1
    with socket.socket() as server:
        server.bind(("127.0.0.1", 0))
        server.listen()
        port = server.getsockname()[1]
        with pytest.raises(SystemExit) as stopped:
            participant_main(["P4", "--port", str(port)])
    assert stopped.value.code == 2
    said = capsys.readouterr().err
    assert said.startswith(f"make teach: port {port} is in use") and said.count("\n") == 1
    with pytest.raises(SystemExit) as stopped:
        participant_main(["P4", "--port", "99999"])
    assert stopped.value.code == 2
    said = capsys.readouterr().err
    assert said == "make teach: PORT (--port) must be a number from 1 to 65535, got 99999\n"
    with pytest.raises(SystemExit) as stopped:
        participant_main(["P4", "--port", "abc"])
    assert stopped.value.code == 2
    assert capsys.readouterr().err == "make teach: PORT (--port): invalid int value: 'abc'\n"
    # A refusal names the setting as make teach's command line gives it, beside the option or field.
    for argv, said in [
        (["--queries", "-1"], "QUERIES (preference_queries) must be an integer >= 1, got -1"),
        (
            ["--domain", "wipng"],
            "DOMAIN (--domain): invalid choice: 'wipng' (choose from 'wiping', 'pushing')",
        ),
    ]:
        with pytest.raises(SystemExit):
            participant_main(["P4", *argv])
        assert capsys.readouterr().err == f"make teach: {said}\n"


def test_make_teach_refuses_a_machine_that_cannot_render_the_clips(results, monkeypatch, capsys):
    monkeypatch.setattr(make_teach, "why_no_gl", lambda: "RuntimeError: no EGL display")
    with pytest.raises(SystemExit) as stopped:
        participant_main(["P8", "--port", str(free_port())])
    assert stopped.value.code == 2
    assert capsys.readouterr().err.startswith(
        "make teach: clips cannot be rendered here (RuntimeError: no EGL display), and a participant judges"
    )


def test_make_teach_removes_the_view_folders_of_servers_killed_outright(tmp_path):
    # A server killed with SIGKILL leaves its view folder; the next `make teach` removes it, and only it.
    gone = subprocess.Popen([sys.executable, "-c", "pass"])
    gone.wait()
    stale = tmp_path / f"{make_teach.VIEW_FOLDER}{gone.pid}-abc"
    live = tmp_path / f"{make_teach.VIEW_FOLDER}{os.getpid()}-def"
    others = [tmp_path / f"{make_teach.VIEW_FOLDER}x-1", tmp_path / "hipref-other-1-2"]
    for folder in (stale, live, *others):
        folder.mkdir()
        (folder / "teach.ipynb").write_text("{}")
    make_teach.remove_stale_views(tmp_path)
    assert not stale.exists()
    assert live.exists() and all(folder.exists() for folder in others)


def test_make_teach_refuses_a_participant_served_before_with_other_settings(results, monkeypatch, capsys):
    monkeypatch.setattr(make_teach, "why_no_gl", lambda: None)
    monkeypatch.setattr(make_teach.signal, "signal", lambda *_: None)
    monkeypatch.setattr(make_teach, "participant_view", lambda _, parameters, out: out)
    monkeypatch.setattr(make_teach, "serve", lambda command, port, ready: None)
    port = str(free_port())
    seed = participant.participant_seed("P9")
    practice = practice_config(TeachConfig(teacher="person", participant="P9", true_parameter=0.6, seed=seed))
    SessionFile(results / "sessions" / "practice" / practice.session_name, practice.header()).close()
    participant_main(["P9", "--port", port, "--true-parameter", "0.6"])  # the same settings: served
    with pytest.raises(SystemExit) as stopped:
        participant_main(["P9", "--port", port])  # the truth forgotten: 0.8, not 0.6
    assert stopped.value.code == 2
    said = capsys.readouterr().err
    # One line naming what differs as make teach's settings, then and now, and the file that holds it.
    assert said == (
        "make teach: participant P9 was served before with other settings (TRUE_PARAMETER=0.6 then, 0.8 now; "
        "sessions/practice/participant_P9_practice.jsonl): serve them with those, or give this session "
        "another id\n"
    )
    with pytest.raises(SystemExit):
        participant_main(["P9", "--port", port, "--true-parameter", "17", "--domain", "pushing"])
    assert "(DOMAIN=wiping then, pushing now, TRUE_PARAMETER=0.6 then, 17.0 now; " in capsys.readouterr().err
    # Every setting that differs in any of the participant's files, and the files, in one refusal.
    served = TeachConfig(
        teacher="person",
        participant="P9",
        true_parameter=0.6,
        seed=seed,
        preference_queries=12,
        catch_every=4,
        conditions=("uniform", "information_gain"),
    )  # as `make teach PARTICIPANT=P9 TRUE_PARAMETER=0.6` serves it
    (first, *_) = participant.condition_configs(served)
    SessionFile(results / "sessions" / first.session_name, first.header()).close()
    with pytest.raises(SystemExit):
        participant_main(["P9", "--port", port, "--true-parameter", "0.7", "--queries", "10"])
    said = capsys.readouterr().err
    assert "(TRUE_PARAMETER=0.6 then, 0.7 now, QUERIES=12 then, 10 now; " in said
    assert "sessions/practice/participant_P9_practice.jsonl, sessions/participant_P9_uniform.jsonl)" in said


def test_make_teach_checks_the_very_headers_the_served_notebook_writes(results, monkeypatch, tmp_path):
    # `check_sessions` builds its headers from the command's settings and TeachConfig's defaults; the kernel
    # builds them from the served view's parameters cell: the two must agree, or a returning participant is
    # refused (or a changed setting let through).
    monkeypatch.setattr(make_teach, "why_no_gl", lambda: None)  # rendering is tested apart
    monkeypatch.setattr(make_teach.signal, "signal", lambda *_: None)  # the test process keeps its handlers
    views: list[Path] = []

    def view(notebook: Path, parameters: dict, out: Path) -> Path:
        views.append(participant.participant_view(notebook, parameters, tmp_path / f"view{len(views)}.ipynb"))
        return views[-1]

    monkeypatch.setattr(make_teach, "participant_view", view)
    monkeypatch.setattr(make_teach, "serve", lambda command, port, ready: None)
    checked: list[TeachConfig] = []
    monkeypatch.setattr(make_teach, "check_sessions", checked.append)
    port = str(free_port())
    participant_main(["P8", "--port", port])
    other = ["--domain", "pushing", "--queries", "5", "--conditions", "uniform"]
    participant_main(["P8", "--port", port, *other])
    assert len(views) == len(checked) == 2
    for path, command in zip(views, checked, strict=True):
        cells = json.loads(path.read_text())["cells"]
        source = next("".join(c["source"]) for c in cells if "parameters" in c["metadata"].get("tags", []))
        namespace: dict = {}
        exec(compile(source, "parameters", "exec", dont_inherit=True), namespace)  # the kernel's first cell
        del namespace["__builtins__"]
        kernel = config_from_parameters(TeachConfig, namespace)
        for of_kernel, of_command in zip(
            [practice_config(kernel), *participant.condition_configs(kernel)],
            [practice_config(command), *participant.condition_configs(command)],
            strict=True,
        ):
            assert of_kernel.header() == of_command.header()
            assert of_kernel.session_name == of_command.session_name


def test_a_participants_world_lies_away_from_the_learners_first_estimate_unless_told(results, monkeypatch):
    monkeypatch.setattr(make_teach, "why_no_gl", lambda: None)  # rendering is tested apart
    monkeypatch.setattr(make_teach.signal, "signal", lambda *_: None)  # the test process keeps its handlers
    served: list[dict] = []
    monkeypatch.setattr(make_teach, "participant_view", lambda _, parameters, out: served.append(parameters))
    monkeypatch.setattr(make_teach, "serve", lambda command, port, ready: None)
    port = str(free_port())
    participant_main(["P5", "--port", port])
    participant_main(["P5", "--port", port, "--domain", "pushing", "--queries", "5"])
    participant_main(["P5", "--port", port, "--true-parameter", "0.55"])
    # The learner starts at the range's middle (0.7 m, 14 kg): a world there would leave nothing to teach.
    assert [(p["domain"], p["true_parameter"]) for p in served] == [
        ("wiping", 0.8),
        ("pushing", 17.0),
        ("wiping", 0.55),
    ]
    assert served[1]["preference_queries"] == 5


def test_a_second_server_for_one_participant_is_refused_naming_the_first(results, monkeypatch, capsys):
    monkeypatch.setattr(make_teach, "why_no_gl", lambda: None)  # rendering is tested apart
    monkeypatch.setattr(make_teach.signal, "signal", lambda *_: None)  # the test process keeps its handlers
    monkeypatch.setattr(make_teach, "participant_view", lambda _, parameters, out: out)
    monkeypatch.setattr(make_teach, "serve", lambda command, port, ready: None)
    port = free_port()
    with make_teach.served_once("P6", 8870):  # the first server, still running
        with pytest.raises(SystemExit) as stopped:
            participant_main(["P6", "--port", str(port)])
        assert stopped.value.code == 2
        assert capsys.readouterr().err.startswith(
            "make teach: participant P6 is served already (at http://127.0.0.1:8870/ on "
        )
        participant_main(["P7", "--port", str(port)])  # another participant is served
    assert (results / "sessions" / "participant_P6.serving").read_text() == ""  # the first server ended
    participant_main(["P6", "--port", str(port)])


def test_conditions_without_a_participant_are_refused():
    with pytest.raises(ValueError, match=r"conditions \['uniform'\] are a participant's .* set participant"):
        TeachConfig(conditions=("uniform",))


def test_notebook_09_run_with_a_participant_shows_the_screens_then_stops_saying_why(
    results, capsys, monkeypatch
):
    """Run All in JupyterLab with `participant` set: the participant's screens, then a one-line stop at the
    first researcher cell (no traceback, no NameError of a session the participant branch did not open)."""
    from IPython.core.interactiveshell import InteractiveShell

    notebook = Path(__file__).resolve().parents[1] / "notebooks" / "09_teach.ipynb"
    code = [c for c in json.loads(notebook.read_text())["cells"] if c["cell_type"] == "code"]
    cells = ["".join(c["source"]) for c in code]
    monkeypatch.setitem(
        sys.modules, "__main__", sys.modules["__main__"]
    )  # the shell replaces it; put it back
    shell = InteractiveShell.instance()
    shell.reset(new_session=False)
    parameters = cells[0] + "\nparticipant = 'P1'\nconditions = ['uniform']\n"
    assert shell.run_cell(parameters).success
    assert shell.run_cell(cells[1]).success  # the participant's screens
    assert not isinstance(shell.user_ns.get("session"), SessionFile)  # no researcher's session opened
    stopped = shell.run_cell(cells[2])
    assert type(stopped.error_in_exec).__name__ == "ParticipantMode"
    shown = capsys.readouterr().out
    assert "[the participant's screens: interactive" in shown  # the screens' widget, shown as plain text
    assert "Stopped here:" in shown and "make teach PARTICIPANT=P1" in shown
    assert "Traceback" not in shown and "NameError" not in shown


def test_warming_builds_every_table_the_first_answer_reads():
    # The tables `warm` builds while the person watches are those telling an answer reads: none is built then.
    learner = BayesLearner(domain_spec("wiping").candidates, BayesConfig(answer_models=person_family()), 3)
    queries._table.cache_clear()
    warm(learner)
    built = queries._table.cache_info().misses
    # A myopic model with memory reads its twin's table without memory (one answer's law is the same).
    assert built == len({dataclasses.replace(m, memory=0.0) for m in person_family()}) < len(person_family())
    learner.tell(learner.ask(), 1)
    assert queries._table.cache_info().misses == built


def test_every_query_is_shown_from_one_layout_and_each_candidate_rendered_once(results, monkeypatch):
    """The clips come from the session's display layout, each candidate's rendered once and shown again
    from memory; after the last answer nothing more is rendered."""
    from hipref.teach import clips as clip_module

    rendered: list[tuple[float, tuple]] = []

    def frames(domain, task, truth, estimate, layout, count):  # a frame whose colour names the candidate
        rendered.append((estimate, tuple(np.concatenate([np.ravel(part) for part in layout]))))
        return [np.full((6, 8, 3), int(estimate * 100) % 256, np.uint8)] * count

    monkeypatch.setattr(clip_module, "annotated_frames", frames)
    config = TeachConfig(**SMALL, frames=3)
    teaching = PreferenceTeaching(config, open_session(config))
    shown_pairs = []
    while (shown := teaching.current) is not None:
        assert shown.animations is not None and len(shown.animations) == 2
        teaching.wait_ready()
        shown_pairs.append([shown.query.candidates[i] for i in shown.order])
        for gif, candidate in zip(shown.animations, shown_pairs[-1], strict=True):
            assert gif == teaching.candidate_clips.gifs[candidate]  # that side's candidate's clip
        teaching.answer("left", 1.0)
    teaching.close()
    estimates = [estimate for estimate, _ in rendered]
    assert len(estimates) == len(set(estimates)), "no candidate rendered twice"
    assert len({layout for _, layout in rendered}) == 1, "one display layout"
    assert {c for pair in shown_pairs for c in pair} <= set(estimates)


def test_without_gl_a_session_tries_rendering_once_and_shows_no_clips(results, monkeypatch):
    from hipref.teach import clips as clip_module

    tried: list[float] = []
    monkeypatch.setattr(clip_module, "annotated_frames", lambda domain, task, truth, e, *_: tried.append(e))
    config = TeachConfig(**SMALL)
    teaching = PreferenceTeaching(config, open_session(config))
    teaching.wait_ready()
    assert teaching.current is not None and teaching.current.animations is None
    teaching.answer("right", 1.0)
    assert teaching.current is not None and teaching.current.animations is None
    teaching.close()
    assert len(tried) == 1
