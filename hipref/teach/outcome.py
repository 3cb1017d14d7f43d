"""What a teaching session changed: the robot executing the task with the estimate before and after it.

The task is executed on physics of its own: the session's is the background thread's, which may be preparing
the next query meanwhile (two threads stepping one MjData corrupt both strokes: the outcome and the next
query's slice).
"""

from __future__ import annotations

import numpy as np

from hipref.envs.task import Task
from hipref.experiments.domains import domain_spec
from hipref.teach.clips import annotated_frames, side_by_side_gif
from hipref.teach.preferences import PreferenceTeaching
from hipref.validation import check_int

OUTCOME_STREAM = 10
"""Salt of the seed sequence the attempts' layouts are drawn from (apart from every stream of the session)."""


def own_task(teaching: PreferenceTeaching) -> Task:
    """A task of the session's domain apart from the session's (whose thread may be executing a query)."""
    return domain_spec(teaching.config.domain).make_task()


def before_and_after(teaching: PreferenceTeaching, attempts: int = 20) -> dict[str, float]:
    """The estimate before any answer and now, their errors, and the task's success with each on the same
    `attempts` layouts (MuJoCo, the real controllers)."""
    check_int("attempts", attempts, 1)
    task, truth = own_task(teaching), teaching.truth
    rng = np.random.default_rng(np.random.SeedSequence([teaching.config.seed, OUTCOME_STREAM]))
    layouts = [task.sample_layout(rng) for _ in range(attempts)]
    result: dict[str, float] = {}
    for when, estimate in (("before", teaching.initial_estimate), ("after", teaching.estimate())):
        result[f"estimate_{when}"] = estimate
        result[f"error_{when}"] = abs(estimate - truth)
        result[f"success_{when}"] = float(
            np.mean([task.rollout(truth, estimate, at).success for at in layouts])
        )
    return result


def before_and_after_clip(teaching: PreferenceTeaching) -> bytes | None:
    """The task executed from one layout with the estimate before the session (left) and now (right), a
    looping GIF; None where no GL is."""
    task, config = own_task(teaching), teaching.config
    layout = task.sample_layout(np.random.default_rng(np.random.SeedSequence([config.seed, OUTCOME_STREAM])))
    frames = [
        annotated_frames(config.domain, task, teaching.truth, estimate, layout, config.frames)
        for estimate in (teaching.initial_estimate, teaching.estimate())
    ]
    clips = [f for f in frames if f is not None]
    return side_by_side_gif(clips, config.fps) if len(clips) == len(frames) else None
