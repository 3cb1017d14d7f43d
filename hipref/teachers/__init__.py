"""Teachers: who answers a learner's query (feedback on actions, preferences over parameters)."""

from hipref.teachers.feedback import (
    FEEDBACK_VALUES,
    FeedbackQuery,
    ScriptedFeedbackTeacher,
    validate_feedback,
)
from hipref.teachers.models import EQUAL, SKIP, TEACHER_KINDS, NoLabel, TeacherModel
from hipref.teachers.preference import (
    PreferenceQuery,
    ScriptedPreferenceTeacher,
    preference_label_vector,
    preferred_index,
)

__all__ = [
    "EQUAL",
    "FEEDBACK_VALUES",
    "SKIP",
    "TEACHER_KINDS",
    "FeedbackQuery",
    "NoLabel",
    "PreferenceQuery",
    "ScriptedFeedbackTeacher",
    "ScriptedPreferenceTeacher",
    "TeacherModel",
    "preference_label_vector",
    "preferred_index",
    "validate_feedback",
]
