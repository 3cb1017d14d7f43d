"""The look shared by every figure of the study."""

from __future__ import annotations

import matplotlib.pyplot as plt
import seaborn as sns

METHOD_LABELS = {
    "tabular_coach": "Tabular COACH (ours)",
    "pretrained_coach": "Pretrained COACH",
    "osi": "OSI",
    "pesi": "PESI",
    "pesi_ce": "PESI, standard CE",
    "co_pesi": "CO-PESI",
    "co_pesi_estimated": "CO-PESI, estimated noise",
    "co_pesi_estimated_same_pair": "CO-PESI, estimated noise (same-pair conflicts)",
    "spd": "SPD",
    "admittance": "Admittance",
    "constant_middle": "Range middle (constant)",
    "constant_best": "Best constant for the truths",
}


def setup() -> None:
    """Seaborn's paper context with a white grid; call once per notebook."""
    sns.set_theme(context="paper", style="whitegrid", font_scale=1.1)
    plt.rcParams["figure.dpi"] = 100
    plt.rcParams["savefig.bbox"] = "tight"


def label(method: str) -> str:
    return METHOD_LABELS.get(method, method)
