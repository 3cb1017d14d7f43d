"""Preferences with a person as the teacher: queries shown as two clips, answers stored, then told.

The learner is notebook 12's Bayesian learner (by default) or PESI (Algorithm 2). Each query is two
candidates from Phi and a slice tau of the clip pi^l executes with one of them from the query's layout.
The person sees the clips of both candidates from the session's display layout, side by side and looping,
on sides drawn at random (the candidates' values are never shown: the person judges the motion), and
answers 'left', 'right' or "can't tell". The answer is appended to the session file before the learner is
told; "can't tell" is stored and told as 'equally good' (PESI has no label for it and only counts it; the
Bayesian learner reads it as the truth lying near the pair's midpoint).

So that the next pair is on screen as soon as the person answers, it is executed and its clips found in
a background thread while the person watches the current one. A candidate's clip is rendered once per
session (`CandidateClips`): every query is shown from one display layout, so a candidate asked again is
shown at once, and while the thread has nothing else to do it renders ahead the candidates nearest the
running estimate. With uniformly drawn candidates the next query does not depend on the answer, so it is
prepared once, the learner being asked one query ahead. With a chosen query rule it does: the next query
is prepared for each possible answer ('left' and 'right' first), each on a copy of the learner and of the
session's random streams, and the copy of the answer given is kept. Resuming replays the stored answers in
the live order with the stored slices, without physics, and rebuilds the learner exactly
(`tests/test_teach_session.py`).

With `catch_every`, every catch_every-th query is a catch trial instead of the learner's: the candidate
nearest the truth against the end of the range farthest from it (`catch_pair`), shown like any query. Its
answer is stored with `catch` true and not told to the learner, so the learner's queries and estimate are
those of the session without catch trials.
"""

from __future__ import annotations

import copy
import threading
import time
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor, wait
from dataclasses import dataclass
from typing import Any

import numpy as np

from hipref.envs.task import Clip, Layout, clip
from hipref.experiments.domains import domain_spec
from hipref.experiments.si_pretraining import pretrained_model
from hipref.learners.sysid import CandidateSet
from hipref.sim.render import release_clip_renderer
from hipref.teach.clips import CandidateClips
from hipref.teach.config import TeachConfig
from hipref.teach.learner import (
    Learner,
    evaluation_slices,
    make_learner,
    running_estimate,
    session_streams,
    warm,
)
from hipref.teach.session import SessionFile
from hipref.teachers.preference import EQUAL, PreferenceQuery
from hipref.validation import check_choice

ANSWERS: tuple[str, ...] = ("left", "right", "cant_tell")
"""What a person may answer to a preference query."""
SIDES: tuple[str, ...] = ("left", "right")


def catch_pair(candidates: CandidateSet, truth: float) -> tuple[float, float]:
    """A catch trial's pair: the candidate nearest `truth`, and the end of the range farthest from it."""
    values = candidates.values
    near = float(values[np.argmin(np.abs(values - truth))])
    far = candidates.low if truth - candidates.low > candidates.high - truth else candidates.high
    return near, float(far)


def tell(learner: Learner, query: PreferenceQuery, label: int | None) -> None:
    """Tell `learner` an answer: its label, or "can't tell" as 'equally good'."""
    learner.tell(query, EQUAL if label is None else label)


def told(learner: Learner, shown: ShownQuery, answer: str) -> None:
    """Tell `learner` the answer to `shown`, unless it is a catch trial."""
    if not shown.catch:
        tell(learner, shown.query, shown.label(answer))


@dataclass(frozen=True)
class ShownQuery:
    """A query as the person sees it."""

    number: int
    """Its place in the session, from 0."""
    query: PreferenceQuery
    """What the learner asked: the candidates (in the learner's order)."""
    clip: Clip
    """The clip tau was cut from."""
    order: tuple[int, ...]
    """order[s]: the index in `query.candidates` of the candidate shown on side s (left, right)."""
    animations: tuple[bytes, ...] | None
    """The candidates' clips in `order` (left, right), each a looping GIF; None without GL or when
    replayed."""
    catch: bool = False
    """A catch trial (`catch_pair`): stored, not told to the learner."""

    def label(self, answer: str) -> int | None:
        """The Eq. 2 label of `answer` (1: candidates[0] preferred), None for "can't tell"."""
        check_choice("answer", answer, ANSWERS)
        if answer == "cant_tell":
            return None
        return 1 if self.order[SIDES.index(answer)] == 0 else -1

    def side_of(self, candidate: int) -> str:
        """The side candidate `candidate` (an index in `query.candidates`) is shown on."""
        return SIDES[self.order.index(candidate)]


def answer_record(shown: ShownQuery, answer: str, seconds: float, seed: int) -> dict[str, Any]:
    """The session file's line for `answer` to `shown` after `seconds`, in a session of `seed`: the pair in
    the learner's order and as shown, the answer and its label, and the clip's slice (for replays)."""
    c = shown.clip
    return {
        "kind": "preference",
        "query": shown.number,
        "candidates": list(shown.query.candidates),
        "order": list(shown.order),
        "shown": [shown.query.candidates[i] for i in shown.order],
        "answer": answer,
        "label": shown.label(answer),
        "seconds": round(float(seconds), 3),
        "seed": seed,
        "catch": shown.catch,
        "clip": {"estimate": c.estimate, "periods": c.periods, "first": c.first, "tau": c.tau.tolist()},
    }


@dataclass
class Asker:
    """What asking a query draws from: the learner and the session's random streams of layouts, sides and
    slices. Copied whole to prepare the query after each possible answer."""

    learner: Learner
    layouts: np.random.Generator
    sides: np.random.Generator
    slices: np.random.Generator


class PreferenceTeaching:
    """A session's preference part: the learner, its queries, the stored answers and the running
    estimate."""

    def __init__(self, config: TeachConfig, session: SessionFile, *, render: bool = True) -> None:
        self.config = config
        self.session = session
        self.render = render
        spec = domain_spec(config.domain)
        self._task = spec.make_task()
        """The physics the queries are executed on, by the thread preparing the next query while the person
        watches: nothing else may execute on it (`hipref.teach.outcome` builds a task of its own)."""
        self.truth = config.true_parameter
        self.history = config.data.history
        streams = session_streams(config)
        model = pretrained_model(config.domain, config.data)
        self._asker = Asker(
            make_learner(config, model),
            np.random.default_rng(streams.layouts),
            np.random.default_rng(streams.sides),
            np.random.default_rng(streams.slices),
        )
        # Beside the thread preparing queries, so that a quick first answer does not wait for it either.
        threading.Thread(target=warm, args=(self._asker.learner,), name="hipref-warm", daemon=True).start()
        self.evaluation = evaluation_slices(config, self._task)
        display = self._task.sample_layout(np.random.default_rng(streams.display))
        self.candidate_clips = CandidateClips(
            config.domain, self._task, self.truth, display, config.frames, config.fps
        )
        """Used by the thread preparing queries only, as `_task` is."""
        self.initial_estimate = running_estimate(self._asker.learner, self.evaluation)
        """The estimate before any answer: what the controller had without the person."""
        # A chosen query rule makes the next query depend on the answer.
        self.answer_dependent = config.query_rule != "uniform"
        self._executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="hipref-next-query")
        self._next: dict[str, Future[tuple[Asker, ShownQuery]]] = {}
        self._answers_given = 0
        self._last_answer: str | None = None
        """Answers given in this process, and the last: a query prepared for another answer than the one
        given is not rendered."""
        self._ahead: Future[None] | None = None
        self._ahead_token = 0
        """Changed to stop the rendering ahead (`_render_ahead`)."""
        self._closed = False
        self.current: ShownQuery | None = None
        # On the thread that prepares every later query: the clips' GL context is that thread's.
        self._executor.submit(self._replay, session.of_kind("preference")).result()

    @property
    def learner(self) -> Learner:
        """The learner told the answers so far."""
        return self._asker.learner

    @property
    def answered(self) -> int:
        return len(self.session.of_kind("preference"))

    @property
    def done(self) -> bool:
        return self.answered >= self.config.preference_queries

    def estimate(self) -> float:
        """The learner's running estimate (`running_estimate`)."""
        return running_estimate(self.learner, self.evaluation)

    # --- asking ---------------------------------------------------------------------------------------

    def _prepare(
        self,
        number: int,
        record: dict[str, Any] | None,
        asker: Asker,
        wanted: Callable[[], bool] = lambda: True,
        clips: CandidateClips | None = None,
    ) -> ShownQuery:
        """Ask `asker`'s learner for query `number`; from `record`'s slice when it was answered. Its clips
        are found in `clips` (the session's by default), rendered there unless `wanted()` says by then that
        the query will not be shown."""
        layout: Layout = self._task.sample_layout(asker.layouts)
        executed: list[Clip] = []
        if record is None:

            def observe(phi: float, rng: np.random.Generator) -> np.ndarray:
                executed.append(clip(self._task, self.truth, phi, layout, self.history, rng))
                return executed[-1].tau

        else:
            stored = record["clip"]
            recorded = Clip(stored["estimate"], stored["periods"], stored["first"], np.array(stored["tau"]))

            def observe(phi: float, rng: np.random.Generator) -> np.ndarray:
                executed.append(recorded)
                return recorded.replay(phi, self.history, rng)

        catch = self.is_catch(number)
        if catch:
            candidates = catch_pair(domain_spec(self.config.domain).candidates, self.truth)
            query = PreferenceQuery(candidates, features=observe(candidates[0], asker.slices))
        else:
            query = asker.learner.ask(observe)
        if not executed:
            # A learner asking by a chosen rule takes no slice; one is cut for the record, so that every
            # learner can be replayed from the session (`hipref.teach.recorded`).
            observe(query.candidates[0], asker.slices)
        order = tuple(int(i) for i in asker.sides.permutation(len(query.candidates)))
        if record is not None and (
            list(query.candidates) != record["candidates"] or list(order) != record["order"]
        ):
            raise ValueError(
                f"{self.session.path}: answer {number} was given to candidates {record['candidates']} shown "
                f"in order {record['order']}, but this session asks {list(query.candidates)} in order "
                f"{list(order)}: the file was written by another version of the study"
            )
        animations = None
        if record is None and self.render and wanted():
            found = [(clips or self.candidate_clips).gif(query.candidates[i]) for i in order]
            animations = tuple(gif for gif in found if gif is not None)
            if len(animations) != len(found):
                animations = None
        return ShownQuery(number, query, executed[0], order, animations, catch)

    def is_catch(self, number: int) -> bool:
        """Whether query `number` (from 0) is a catch trial."""
        every = self.config.catch_every
        return every > 0 and (number + 1) % every == 0

    def prepare_apart(self, number: int) -> ShownQuery:
        """Query `number` asked, executed and rendered on a copy of the session's learner and streams,
        nothing kept, its clips rendered afresh: what a query costs when nothing was prepared ahead
        (`hipref.bench.teach`). Waits for the background thread's work first: both execute on the session's
        task."""
        self._ahead_token += 1
        pending: list[Future[Any]] = [*self._next.values()]
        wait(pending + ([self._ahead] if self._ahead else []))
        clips = self.candidate_clips
        fresh = CandidateClips(clips.domain, self._task, self.truth, clips.layout, clips.frames, clips.fps)
        return self._prepare(number, None, copy.deepcopy(self._asker), clips=fresh)

    def _render_ahead(self, nearest_first: list[float], token: int) -> None:
        """Render the clips of `nearest_first` not rendered yet, one after another, until `_ahead_token`
        changes: the person answered (the next query's preparation comes first) or the session closes."""
        for candidate in nearest_first:
            if self._ahead_token != token or not self.candidate_clips.available:
                return
            self.candidate_clips.gif(candidate)

    def _branch(
        self, asker: Asker, shown: ShownQuery, answer: str | None, answers_given: int
    ) -> tuple[Asker, ShownQuery]:
        """The query after `shown` on `asker` (a copy), told `answer` to `shown` first when it matters."""
        if answer is not None:
            told(asker.learner, shown, answer)

        def wanted() -> bool:  # still possible: not yet answered, or answered `answer`
            return self._answers_given == answers_given or self._last_answer in (answer, None)

        return asker, self._prepare(shown.number + 1, None, asker, wanted)

    def _prefetch(self) -> None:
        """Start preparing the query after the current one, if the session plans one: once, or for each
        possible answer (on copies) when the next query depends on it; then render clips ahead, the
        candidates nearest the running estimate first."""
        self._next = {}
        if self.current is None or self.current.number + 1 >= self.config.preference_queries:
            return
        nearest_first: list[float] = []
        if self.render:  # read before the uniform rule's branch asks on the live learner
            values = domain_spec(self.config.domain).candidates.values
            order = np.argsort(np.abs(values - self.estimate()), kind="stable")
            nearest_first = [float(v) for v in values[order]]
        given = self._answers_given
        if not self.answer_dependent:
            # Asked one ahead on the live learner; it is told the current answer once this is done.
            future = self._executor.submit(self._branch, self._asker, self.current, None, given)
            self._next = dict.fromkeys(ANSWERS, future)
        else:
            for answer in ANSWERS:
                branch = copy.deepcopy(self._asker)
                self._next[answer] = self._executor.submit(self._branch, branch, self.current, answer, given)
        if self.render:
            self._ahead = self._executor.submit(self._render_ahead, nearest_first, self._ahead_token)

    def _replay(self, records: list[dict[str, Any]]) -> None:
        """Rebuild the learner from the stored answers, in the live order: ask k + 1 then tell k (uniform
        queries), or tell k then ask k + 1 (a chosen rule)."""
        planned = self.config.preference_queries
        if self.answer_dependent:
            for k, record in enumerate(records):
                shown = self._prepare(k, record, self._asker)
                told(self.learner, shown, record["answer"])
            following = len(records)
            self.current = self._prepare(following, None, self._asker) if following < planned else None
        elif records:
            self.current = self._prepare(0, records[0], self._asker)
            for k, record in enumerate(records):
                following = k + 1
                upcoming = None
                if following < planned:
                    stored = records[following] if following < len(records) else None
                    upcoming = self._prepare(following, stored, self._asker)
                assert self.current is not None
                told(self.learner, self.current, record["answer"])
                self.current = upcoming
        else:
            self.current = self._prepare(0, None, self._asker)
        self._prefetch()

    # --- answering ------------------------------------------------------------------------------------

    def answer(self, answer: str, seconds: float) -> None:
        """The person's `answer` to the current query after `seconds`: stored, then told to the learner;
        the next query (already being prepared) becomes current."""
        check_choice("answer", answer, ANSWERS)
        shown = self.current
        if shown is None:
            raise RuntimeError("every planned preference query has been answered")
        self.session.append(answer_record(shown, answer, seconds, self.config.seed))
        branch = self._next.get(answer)
        # The branches of the other answers stop before rendering their clips. The answer is set before the
        # count, which `wanted` reads first: a branch that sees the new count sees the new answer.
        self._last_answer = answer if self.answer_dependent else None
        self._answers_given += 1
        self._ahead_token += 1
        for other in self._next.values():
            if other is not branch:
                other.cancel()
        if branch is None:  # the last planned query
            told(self.learner, shown, answer)
            self.current = None
        else:
            asker, upcoming = branch.result()
            if not self.answer_dependent:
                told(asker.learner, shown, answer)
            self._asker, self.current = asker, upcoming
        self._prefetch()

    def wait_ready(self) -> float:
        """Block until the query after the current one is prepared (for every answer); the seconds waited."""
        start = time.perf_counter()
        for future in self._next.values():
            future.result()
        return time.perf_counter() - start

    def close(self) -> None:
        """Stop the background thread (after the query or clip it is preparing), its GL context freed."""
        if self._closed:
            return
        self._closed = True
        self._ahead_token += 1
        waiting: list[Future[Any]] = [*self._next.values()]
        for future in waiting + ([self._ahead] if self._ahead else []):
            future.cancel()
        self._executor.submit(release_clip_renderer)
        self._executor.shutdown(wait=True)
