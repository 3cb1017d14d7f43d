"""What the answers of the teaching sessions say, person by person (the table of `hipref.teach.dataset`).

- `per_participant`: agreement with the truth (with a 95% bootstrap interval) overall and on catch trials,
  answer times and answers too fast to have watched the clips, the consistency of answers to a pair asked
  again, and the flip rate: from the truth (1 - agreement) and inferred from the answers alone by the
  marginal-likelihood and repeated-pair estimators (`hipref.learners.noise_rate`, notebook 06).
- `psychometric`: P(answer agrees with the truth) against the pair's distance |a - b|, in bins.
- `agreement_across_people`: Krippendorff's alpha (nominal) on the pairs several people answered.
- `learner_estimates`: every learner's estimate from each session's answers (the replay of
  `hipref.teach.recorded`).

A person is a (participant, session): one session has one truth, which the flip-rate estimators assume.
"Can't tell" answers and pairs equally near the truth are left out of agreement; answers with no recorded
time are left out of the times.
"""

from __future__ import annotations

import dataclasses
import os
from collections import Counter
from collections.abc import Hashable, Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from hipref.experiments.domains import domain_spec
from hipref.intervals import bootstrap_mean
from hipref.learners.noise_estimation import PreferenceSet
from hipref.learners.noise_rate import likelihood_noise, repeated_pair_noise
from hipref.teach.config import TeachConfig
from hipref.teach.dataset import read_records
from hipref.teach.recorded import estimates
from hipref.validation import check_range

PERSON: tuple[str, ...] = ("participant", "session")
"""The columns that tell one person's session from another's."""

MIN_VIEWING_SECONDS = 1.0
"""Answers faster than this (s) are too fast to have watched the clips: half a loop of the default clips
(20 frames at 10 fps, 2 s). The scripted stand-in answers at once (0 s is recorded)."""

DISTANCE_BINS: tuple[float, ...] = (0.0, 0.125, 0.25, 0.5, 1.0)
"""Edges of the psychometric curve's bins of |a - b|, as a share of the domain's parameter range."""


def _labelled(rows: pd.DataFrame) -> PreferenceSet:
    kept = rows[rows["label"].notna()]
    return PreferenceSet(
        first=kept["candidate_a"].to_numpy(float),
        second=kept["candidate_b"].to_numpy(float),
        label=kept["label"].to_numpy(int),
    )


def _share(values: pd.Series, resamples: int, seed: int) -> tuple[float, float, float, int]:
    """Mean of booleans (NA left out) with its 95% bootstrap interval, and the count; NaN when empty."""
    kept = values.dropna().to_numpy(float)
    if kept.size == 0:
        return np.nan, np.nan, np.nan, 0
    d = bootstrap_mean(kept, resamples=resamples, seed=seed)
    return d.mean, d.low, d.high, d.n


def _consistency(rows: pd.DataFrame) -> tuple[int, float]:
    """Pairs asked more than once, and the share of pairs of answers to one pair that agree."""
    kept = rows[rows["label"].notna()]
    lower = np.minimum(kept["candidate_a"], kept["candidate_b"]).round(9)
    higher = np.maximum(kept["candidate_a"], kept["candidate_b"]).round(9)
    chose_lower = (kept["chosen"].round(9) == lower).astype(float)
    grouped = chose_lower.groupby([lower, higher])
    asked, lower_chosen = grouped.size().to_numpy(float), grouped.sum().to_numpy(float)
    pairs_of_answers = (asked * (asked - 1) / 2).sum()
    if pairs_of_answers == 0:
        return 0, np.nan
    agreeing = (
        lower_chosen * (lower_chosen - 1) / 2 + (asked - lower_chosen) * (asked - lower_chosen - 1) / 2
    ).sum()
    return int((asked > 1).sum()), float(agreeing / pairs_of_answers)


def per_participant(
    table: pd.DataFrame,
    *,
    fast_seconds: float = MIN_VIEWING_SECONDS,
    resamples: int = 2000,
    seed: int = 0,
) -> pd.DataFrame:
    """One row per person (`PERSON`): counts, agreement with the truth and its interval, on catch
    trials, answer times, answers faster than `fast_seconds`, repeated-pair consistency and flip rates."""
    check_range("fast_seconds", fast_seconds, 0.0, np.inf)
    out = []
    for (participant, session), rows in table.groupby(list(PERSON), sort=True):
        agreement, low, high, judged = _share(rows["agrees"], resamples, seed)
        catch, _, _, catches = _share(rows.loc[rows["catch_trial"], "agrees"], resamples, seed)
        seconds = rows["seconds"].dropna()
        repeated, consistency = _consistency(rows)
        data = _labelled(rows)
        candidates = domain_spec(rows["domain"].iloc[0]).candidates
        out.append(
            {
                "participant": participant,
                "session": session,
                "teacher": rows["teacher"].iloc[0],
                "answers": len(rows),
                "cant_tell": int((rows["answer"] == "cant_tell").sum()),
                "judged": judged,
                "agreement": agreement,
                "agreement_low": low,
                "agreement_high": high,
                "catch_trials": catches,
                "catch_agreement": catch,
                "median_seconds": float(seconds.median()) if len(seconds) else np.nan,
                "too_fast": int((seconds < fast_seconds).sum()),
                "too_fast_share": float((seconds < fast_seconds).mean()) if len(seconds) else np.nan,
                "repeated_pairs": repeated,
                "repeated_consistency": consistency,
                "flip_rate_truth": 1.0 - agreement,
                "flip_rate_likelihood": likelihood_noise(data, candidates.low, candidates.high)
                if len(data)
                else np.nan,
                "flip_rate_repeated": repeated_pair_noise(data) if len(data) else np.nan,
            }
        )
    return pd.DataFrame(out)


def psychometric(
    table: pd.DataFrame,
    *,
    bins: Sequence[float] = DISTANCE_BINS,
    resamples: int = 2000,
    seed: int = 0,
) -> pd.DataFrame:
    """P(correct) per person and bin of the pair's distance |a - b| (a share of the domain's range, bins
    closed on the right): columns participant, session, distance_low, distance_high, n, p_correct, low,
    high (95% bootstrap interval; NaN bounds over fewer than 5 answers)."""
    edges = np.asarray(bins, dtype=float)
    if edges.size < 2 or np.any(np.diff(edges) <= 0):
        raise ValueError(f"bins must be at least two increasing edges, got {list(bins)}")
    width = table["domain"].map(lambda d: domain_spec(d).candidates.high - domain_spec(d).candidates.low)
    share = table["distance"] / width.astype(float)
    place = np.searchsorted(edges, share.to_numpy(float), side="left") - 1
    out = []
    for (participant, session), rows in table.assign(bin=place).groupby(list(PERSON), sort=True):
        for k in range(edges.size - 1):
            p, low, high, n = _share(rows.loc[rows["bin"] == k, "agrees"], resamples, seed)
            out.append(
                {
                    "participant": participant,
                    "session": session,
                    "distance_low": edges[k],
                    "distance_high": edges[k + 1],
                    "n": n,
                    "p_correct": p,
                    "low": low,
                    "high": high,
                }
            )
    return pd.DataFrame(out)


def krippendorff_alpha(units: Sequence[Sequence[Hashable]]) -> float:
    """Krippendorff's alpha for nominal values: each unit the values its coders gave (any number each).
    Units with fewer than two values are not pairable and are left out. NaN when nothing is pairable or
    every value is the same (no disagreement is expected, so none can be measured)."""
    pairable = [Counter(u) for u in units if len(u) >= 2]
    if not pairable:
        return float("nan")
    # Observed disagreement: per unit, the ordered pairs of different values over (values in it - 1).
    observed = sum((c.total() ** 2 - sum(v * v for v in c.values())) / (c.total() - 1) for c in pairable)
    totals: Counter[Hashable] = sum(pairable, Counter())
    n = float(totals.total())
    expected = n**2 - float(sum(v * v for v in totals.values()))
    if expected == 0:
        return float("nan")
    return float(1.0 - (n - 1) * observed / expected)


def agreement_across_people(table: pd.DataFrame) -> tuple[float, int, int]:
    """Krippendorff's alpha on the pairs (same domain and truth) that several people answered, each
    person's first labelled answer to a pair read as 'the lower' or 'the higher' candidate: (alpha, pairs,
    people). NaN with no pair answered by two people."""
    kept = table[table["label"].notna()].copy()
    kept["lower"] = np.minimum(kept["candidate_a"], kept["candidate_b"]).round(9)
    kept["higher"] = np.maximum(kept["candidate_a"], kept["candidate_b"]).round(9)
    kept["value"] = np.where(kept["chosen"].round(9) == kept["lower"], "lower", "higher")
    pair = ["domain", "true_parameter", "lower", "higher"]
    first = kept.sort_values("query", kind="stable").drop_duplicates([*pair, *PERSON])
    shared = first[first.groupby(pair)["value"].transform("size") >= 2]
    units = [list(rows["value"]) for _, rows in shared.groupby(pair, sort=True)]
    people = shared[list(PERSON)].drop_duplicates().shape[0]
    return krippendorff_alpha(units), len(units), people


def learner_estimates(folder: str | os.PathLike[str]) -> pd.DataFrame:
    """Every learner's estimate from each session's answers (`hipref.teach.recorded.estimates`: OSI told
    nothing, PESI, CO-PESI with its noise estimated, the Bayesian learner), from the stored slices; columns
    participant, session, method, estimate, error. Pretrains the sessions' SI model if it is not cached."""
    fields = {f.name for f in dataclasses.fields(TeachConfig)}
    out = []
    for path in sorted(Path(folder).glob("*.jsonl")):
        header, records = read_records(path)
        if not records:
            continue
        config = TeachConfig(**{k: v for k, v in header.items() if k in fields})
        for method, estimate in estimates(config, records).items():
            out.append(
                {
                    "participant": str(header.get("participant", path.stem)),
                    "session": path.name,
                    "method": method,
                    "estimate": estimate,
                    "error": abs(estimate - config.true_parameter),
                }
            )
    return pd.DataFrame(out, columns=["participant", "session", "method", "estimate", "error"])
