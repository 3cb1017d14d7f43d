"""A person teaches the robot from JupyterLab (notebook 09): preferences for SI, feedback for COACH.

- `config`: the session's parameters (`TeachConfig`).
- `session`: the answers file, each answer written before the learner is told.
- `preferences`, `feedback`: the learners with a person as teacher, resumable from the file.
- `clips`: two clips side by side as a looping GIF.
- `notice`: what a participant's page says when its server stops or its kernel dies.
- `app`: the widgets, and the scripted stand-in that presses them.
- `recorded`: a stored session as a teacher, replayed into PESI, CO-PESI, the Bayesian learner and the noise
  estimators.
- `outcome`: the task executed with the estimate before and after a session.
- `dataset`: every session file of a folder as one table of answers (CSV, Parquet, data card).
- `answers`: what the table says person by person: agreement, answer times, consistency, flip rates, the
  psychometric curve, agreement across people, the learners' estimates.
"""

from __future__ import annotations

from hipref.results import results_dir
from hipref.teach.config import TeachConfig
from hipref.teach.session import SessionFile


def open_session(config: TeachConfig) -> SessionFile:
    """The session file of `config` under the results directory's `sessions/`: a person's resumes where
    it stopped; the scripted stand-in's is started afresh (its answers are reproducible)."""
    path = results_dir() / "sessions" / config.session_name
    return SessionFile(path, config.header(), fresh=config.teacher == "scripted")
