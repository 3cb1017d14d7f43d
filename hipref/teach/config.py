"""The parameters of a teaching session (notebook 09)."""

from __future__ import annotations

import dataclasses
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any

from hipref.experiments.domains import domain_spec
from hipref.experiments.si_pretraining import PretrainData
from hipref.learners.queries import QUERY_RULES
from hipref.validation import Integer, OneOf, Range, check_fields, check_range

TEACHERS: tuple[str, ...] = ("person", "scripted")
"""Who answers: a person at the widgets, or a scripted stand-in that presses the same buttons."""

LEARNERS: tuple[str, ...] = ("bayes", "pesi")
"""Who is told the preferences: notebook 12's Bayesian learner (told nothing of the teacher) or PESI."""


@dataclass(frozen=True)
class TeachConfig:
    """A session: preferences for a learner of SI (the Bayesian learner of notebook 12, or PESI, Algorithm
    2) in one environment, then one feedback episode of tabular COACH on the wiping grid (Eq. 1)."""

    teacher: Annotated[str, OneOf(TEACHERS)] = "scripted"
    """'person' (answer with the mouse or the keys) or 'scripted' (a stand-in presses the buttons: how
    papermill and nbval run the notebook)."""
    domain: str = "wiping"
    """The preferences' world: 'wiping' (desk height) or 'pushing' (cube mass)."""
    true_parameter: float = 0.8
    """The environment's unknown parameter (m or kg), inside the domain's range; hidden from the person
    unless `reveal_truth`. Not the range's middle, where the learner starts: the session would have nothing
    to teach."""
    seed: Annotated[int, Integer(0)] = 0
    """Seed of the queries, the layouts, the sides the candidates are shown on and the stand-in."""
    preference_queries: Annotated[int, Integer(1)] = 6
    """Preference queries planned (the learner's learning episodes)."""
    learner: Annotated[str, OneOf(LEARNERS)] = "bayes"
    """Who is told the preferences, one of LEARNERS: 'bayes', the learner notebook 12 found to use every
    answer (told nothing of the teacher, it weighs every teacher model), or 'pesi' (Algorithm 2)."""
    query_rule: Annotated[str, OneOf(QUERY_RULES)] = "information_gain"
    """How the next pair is chosen (`hipref.learners.queries`): 'information_gain' (the pair whose answer
    tells most), 'thompson', 'volume_removal', or 'uniform' (Algorithm 2's uniform draws)."""
    feedback_steps: Annotated[int, Integer(1)] = 6
    """Length in high-level steps of the feedback episode (A.7 allows 290; a person's episode is short)."""
    desk_height: float = 0.7
    """Desk height in m of the feedback episode, known to its controller (R1 is about the high level)."""
    frames: Annotated[int, Integer(2, 200)] = 20
    """Frames of a clip at `fps`: it lasts frames / fps seconds, sped up if the motion is longer (rendering
    is most of what preparing a query costs, so few)."""
    fps: Annotated[int, Integer(1, 60)] = 10
    """Frames per second of the clips."""
    reveal_truth: bool = False
    """Show the true parameter and the estimate's error after each answer."""
    scripted_noise: Annotated[float, Range(0.0, 1.0)] = 0.2
    """The stand-in's flip rate: the fraction of its preferences it answers wrongly (as the scripted
    teacher of section 5)."""
    session: str = ""
    """File name of the session under the results directory's `sessions/`; '' names it after the teacher,
    the domain and the seed. A person's session resumes from it; the stand-in's is written afresh."""
    n_trajectories: int = 300
    """Algorithm 4 trajectories SI is pretrained on (the full profile: 3000, the SI studies'
    model, reused; A.7: 100)."""
    pretrain_steps: int = 500
    """Adam steps of Algorithm 4 (the full profile: 3000)."""
    catch_every: Annotated[int, Integer(0)] = 0
    """Every `catch_every`-th preference query is a catch trial (0: none): the candidate nearest the truth
    against the end of the range farthest from it, which anyone watching can tell apart. Its answer is
    stored flagged `catch` and not told to the learner."""
    participant: str = ""
    """A participant's id (letters, digits, - and _): '' is the researcher's notebook; set, the notebook
    shows the participant's screens (`hipref.teach.participant`, served by `make teach`)."""
    conditions: tuple[Annotated[str, OneOf(QUERY_RULES)], ...] = ()
    """The participant's query rules, in the order they meet them (one session each); () is `query_rule`
    alone."""

    def __post_init__(self) -> None:
        check_fields(self)
        candidates = domain_spec(self.domain).candidates
        check_range("true_parameter", self.true_parameter, candidates.low, candidates.high)
        heights = domain_spec("wiping").candidates
        check_range("desk_height", self.desk_height, heights.low, heights.high)
        if self.participant and not re.fullmatch(r"[A-Za-z0-9_-]{1,40}", self.participant):
            raise ValueError(
                f"participant must be 1-40 letters, digits, - or _ (it names the session files), got "
                f"{self.participant!r}"
            )
        if self.conditions and not self.participant:
            raise ValueError(
                f"conditions {list(self.conditions)} are a participant's (one session each): set participant "
                "to an id for participant mode, or leave conditions [] and choose the session's query_rule"
            )
        if self.session and (Path(self.session).name != self.session or not self.session.endswith(".jsonl")):
            raise ValueError(f"session must be a file name ending in .jsonl, got {self.session!r}")
        self.data  # noqa: B018 - validates n_trajectories and pretrain_steps

    @property
    def data(self) -> PretrainData:
        """Algorithm 4's data and pretraining: the SI studies' model."""
        return PretrainData(self.n_trajectories, pretrain_steps=self.pretrain_steps)

    @property
    def session_name(self) -> str:
        if self.session:
            return self.session
        if self.participant:
            return f"participant_{self.participant}_{self.query_rule}.jsonl"
        return f"{self.teacher}_{self.domain}_seed{self.seed}.jsonl"

    def header(self) -> dict[str, Any]:
        """What a session file records of its session: every field that changes the queries or answers,
        and the participant (catch trials, participant and conditions only when set)."""
        shown = {"teacher", "session", "reveal_truth", "fps"}
        header = {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.name not in shown}
        for name in ("catch_every", "participant", "conditions"):
            if not header[name]:
                del header[name]
        if "conditions" in header:
            header["conditions"] = list(header["conditions"])
        return header
