"""PESI (Algorithm 2) with a person as the teacher: queries shown as two clips, answers stored, then told.

Each query is what `PESILearner.ask` draws: two candidates from Phi and a slice tau of the clip pi^l
executes with one of them. The person sees the clips of both candidates from one layout, side by side and
looping, on sides drawn at random (the candidates' values are never shown: the person judges the motion),
and answers 'left', 'right' or "can't tell". The answer is appended to the session file before PESI is
told; "can't tell" is stored but gives PESI no label (Eq. 2 has no y for it).

So that the next pair is on screen as soon as the person answers, query k + 1 is executed and rendered in
a background thread while the person watches query k: the learner is asked one query ahead. With
Algorithm 2's uniformly drawn candidates a query does not depend on the answers, so this changes nothing
but the waiting. Resuming replays the stored answers in the same order (ask k + 1, then tell k) with the
stored slices, without physics, and rebuilds the learner exactly (`tests/test_teach_session.py`).
"""

from __future__ import annotations

import time
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from hipref.envs.task import Clip, Layout, Task, clip, probe_slice
from hipref.experiments.domains import domain_spec
from hipref.experiments.si_pretraining import pretrained_model
from hipref.learners.pesi import PESIConfig, PESILearner
from hipref.seeds import integer_seed
from hipref.teach.clips import side_by_side_gif
from hipref.teach.config import TeachConfig
from hipref.teach.session import SessionFile
from hipref.teachers.preference import PreferenceQuery
from hipref.validation import check_choice

ANSWERS: tuple[str, ...] = ("left", "right", "cant_tell")
"""What a person may answer to a preference query."""
SIDES: tuple[str, ...] = ("left", "right")
EVALUATION_SLICES = 3
"""Probing slices the running estimate is the mean of (SI's multi-slice estimate)."""


class SessionStreams(NamedTuple):
    """A session's independent random streams, children of its seed."""

    learner: np.random.SeedSequence
    layouts: np.random.SeedSequence
    sides: np.random.SeedSequence
    evaluation: np.random.SeedSequence


def session_streams(config: TeachConfig) -> SessionStreams:
    return SessionStreams(*np.random.SeedSequence([config.seed, 9]).spawn(4))


def evaluation_slices(config: TeachConfig, task: Task) -> np.ndarray:
    """The probing slices the session's running estimate is read on (SI's multi-slice estimate)."""
    rng = np.random.default_rng(session_streams(config).evaluation)
    h = config.data.history
    return np.stack([probe_slice(task, config.true_parameter, h, rng) for _ in range(EVALUATION_SLICES)])


@dataclass(frozen=True)
class ShownQuery:
    """A query as the person sees it."""

    number: int
    """Its place in the session, from 0."""
    query: PreferenceQuery
    """What PESI asked: the candidates (in the learner's order) and tau."""
    clip: Clip
    """The clip tau was cut from."""
    order: tuple[int, ...]
    """order[s]: the index in `query.candidates` of the candidate shown on side s (left, right)."""
    animation: bytes | None
    """The candidates' clips side by side in `order`, a looping GIF; None without GL or when replayed."""

    def label(self, answer: str) -> int | None:
        """The Eq. 2 label of `answer` (1: candidates[0] preferred), None for "can't tell"."""
        check_choice("answer", answer, ANSWERS)
        if answer == "cant_tell":
            return None
        return 1 if self.order[SIDES.index(answer)] == 0 else -1

    def side_of(self, candidate: int) -> str:
        """The side candidate `candidate` (an index in `query.candidates`) is shown on."""
        return SIDES[self.order.index(candidate)]


class PreferenceTeaching:
    """A session's preference part: PESI, its queries, the stored answers and the running estimate."""

    def __init__(self, config: TeachConfig, session: SessionFile, *, render: bool = True) -> None:
        self.config = config
        self.session = session
        self.render = render
        spec = domain_spec(config.domain)
        self.task = spec.make_task()
        self.truth = config.true_parameter
        self.history = config.data.history
        streams = session_streams(config)
        model = pretrained_model(config.domain, config.data)
        pesi = PESIConfig(batch_size=spec.batch_size, history=self.history)
        self.learner = PESILearner(model, pesi, integer_seed(streams.learner))
        self._layouts = np.random.default_rng(streams.layouts)
        self._sides = np.random.default_rng(streams.sides)
        self.evaluation = evaluation_slices(config, self.task)
        self._executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="hipref-next-query")
        self._next: Future[ShownQuery] | None = None
        self.current: ShownQuery | None = None
        self._replay(session.of_kind("preference"))

    @property
    def answered(self) -> int:
        return len(self.session.of_kind("preference"))

    @property
    def done(self) -> bool:
        return self.answered >= self.config.preference_queries

    def estimate(self) -> float:
        """SI's running estimate: the mean of E_Pr[phi] over the session's probing slices."""
        return float(self.learner.model.predict(self.evaluation).mean())

    # --- asking ---------------------------------------------------------------------------------------

    def _prepare(self, number: int, record: dict[str, Any] | None) -> ShownQuery:
        """Ask PESI for query `number` (Algorithm 2, l.2-3); from `record`'s slice when it was answered."""
        layout: Layout = self.task.sample_layout(self._layouts)
        executed: list[Clip] = []
        if record is None:

            def observe(phi: float, rng: np.random.Generator) -> np.ndarray:
                executed.append(clip(self.task, self.truth, phi, layout, self.history, rng))
                return executed[-1].tau

        else:
            stored = record["clip"]
            executed.append(
                Clip(stored["estimate"], stored["periods"], stored["first"], np.array(stored["tau"]))
            )

            def observe(phi: float, rng: np.random.Generator) -> np.ndarray:
                return executed[0].replay(phi, self.history, rng)

        query = self.learner.ask(observe)
        order = tuple(int(i) for i in self._sides.permutation(len(query.candidates)))
        if record is not None and (
            list(query.candidates) != record["candidates"] or list(order) != record["order"]
        ):
            raise ValueError(
                f"{self.session.path}: answer {number} was given to candidates {record['candidates']} shown "
                f"in order {record['order']}, but this session asks {list(query.candidates)} in order "
                f"{list(order)}: the file was written by another version of the study"
            )
        animation = None
        if record is None and self.render:
            frames = [
                self.task.clip_frames(self.truth, query.candidates[i], layout, self.config.frames)
                for i in order
            ]
            if all(f is not None for f in frames):
                animation = side_by_side_gif(frames, self.config.fps)  # type: ignore[arg-type]
        return ShownQuery(number, query, executed[0], order, animation)

    def _prefetch(self) -> None:
        """Start executing and rendering the query after the current one, if the session plans one."""
        self._next = None
        if self.current is not None and self.current.number + 1 < self.config.preference_queries:
            self._next = self._executor.submit(self._prepare, self.current.number + 1, None)

    def _replay(self, records: list[dict[str, Any]]) -> None:
        """Rebuild PESI from the stored answers, in the live order: ask k + 1, then tell k."""
        if records:
            self.current = self._prepare(0, records[0])
            for k, record in enumerate(records):
                following = k + 1
                upcoming = None
                if following < self.config.preference_queries:
                    stored = records[following] if following < len(records) else None
                    upcoming = self._prepare(following, stored)
                self._tell(self.current, record["answer"])
                self.current = upcoming
        elif self.config.preference_queries > 0:
            self.current = self._prepare(0, None)
        self._prefetch()

    # --- answering ------------------------------------------------------------------------------------

    def _tell(self, shown: ShownQuery, answer: str) -> None:
        label = shown.label(answer)
        if label is not None:
            self.learner.tell(shown.query, label)

    def answer(self, answer: str, seconds: float) -> None:
        """The person's `answer` to the current query after `seconds`: stored, then told to PESI; the next
        query (already being prepared) becomes current."""
        check_choice("answer", answer, ANSWERS)
        shown = self.current
        if shown is None:
            raise RuntimeError("every planned preference query has been answered")
        c = shown.clip
        self.session.append(
            {
                "kind": "preference",
                "query": shown.number,
                "candidates": list(shown.query.candidates),
                "order": list(shown.order),
                "shown": [shown.query.candidates[i] for i in shown.order],
                "answer": answer,
                "label": shown.label(answer),
                "seconds": round(float(seconds), 3),
                "seed": self.config.seed,
                "clip": {
                    "estimate": c.estimate,
                    "periods": c.periods,
                    "first": c.first,
                    "tau": c.tau.tolist(),
                },
            }
        )
        upcoming = self._next.result() if self._next is not None else None
        self._tell(shown, answer)
        self.current = upcoming
        self._prefetch()

    def wait_ready(self) -> float:
        """Block until the query after the current one is prepared; the seconds waited."""
        start = time.perf_counter()
        if self._next is not None:
            self._next.result()
        return time.perf_counter() - start

    def close(self) -> None:
        """Stop the background thread (after the query it is preparing)."""
        self._executor.shutdown(wait=True, cancel_futures=True)
