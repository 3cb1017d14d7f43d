"""Teachers: who answers a learner's query (feedback on actions, preferences over parameters)."""

from hipref.teachers.feedback import (
    FEEDBACK_VALUES,
    FeedbackQuery,
    ScriptedFeedbackTeacher,
    validate_feedback,
)
from hipref.teachers.preference import (
    PreferenceQuery,
    ScriptedPreferenceTeacher,
    preference_label_vector,
    preferred_index,
)

__all__ = [
    "FEEDBACK_VALUES",
    "FeedbackQuery",
    "PreferenceQuery",
    "ScriptedFeedbackTeacher",
    "ScriptedPreferenceTeacher",
    "preference_label_vector",
    "preferred_index",
    "validate_feedback",
]
