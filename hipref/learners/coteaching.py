"""CO-PESI: PESI whose SI updates see only the preferences two co-teaching classifiers trust (Algorithm 1).

The classifiers M_0, M_1 and their small-loss selection are in `hipref.learners.coteaching_pair`; here is
the schedule that drives them (start, refresh, rounds, forget-rate ramp), the one SI update per preference
on the last b_0, and the filter's precision and recall against the teacher's recorded flips.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Annotated, Any, ClassVar

import numpy as np

from hipref.learners.coteaching_pair import CoTeachingPair, classifier_inputs
from hipref.learners.filters import Filter, SILearner, UpdateLog
from hipref.validation import Integer, NonEmptyTuple, OneOf, Range, check_fields

REFRESH_UNITS: tuple[str, ...] = ("preferences", "steps")
"""What f_refresh counts: received preferences |D| (default) or classifier co-teaching steps (the
reset-every-step schedule, kept for the sensitivity study)."""
RAMP_ORIGINS: tuple[str, ...] = ("refresh", "start")
"""Where the forget-rate ramp starts: at every (re-)initialisation of M_0, M_1, or once at the first step."""


@dataclass(frozen=True)
class CoTeaching:
    """Algorithm 1, the co-teaching filter of a preference learner, which makes PESI CO-PESI (Table 2 for
    desk height; cube mass uses 32 for refresh_frequency, and for the learner's batch_size and start_size).

    `noise_level`, the fraction of flipped preferences assumed, is the learner's flip rate: the true one
    (co_pesi), or an estimate (A.9) for co_pesi_estimated. Following A.7 the remember rate is
    1 - noise_level, so the final forget rate is noise_level and n_forget = round(forget_rate * batch).

    The schedule, per received preference. While |D| <= s: one SI update by Eq. 2 on an unfiltered batch,
    as PESI makes (`update_before_start`). Afterwards: re-initialise M_0, M_1 if |D| has just reached a
    multiple of f_refresh (l.6-7), run t = `rounds` classifier co-teaching steps (l.9-13: sample a batch,
    select by small loss, cross-update), then ONE SI update by Eq. 2 on the last step's b_0 (l.14). CO-PESI
    thus makes exactly one SI update per preference, as PESI does, and comparing the two isolates the filter.

    Why rounds: with one classifier step per preference and a refresh every 16 such steps
    (`reset_every_step_schedule`), M_0 and M_1 never train on more than 16 minibatches, too few to learn
    the (pair -> label) rule well: a pair separates flipped from clean labels after some hundred steps
    (tests/test_coteaching.py).

    How t was chosen: the filter's precision (flipped share of the forgotten samples) and recall
    (`PESILearner.filter_precision_recall`) on synthetic preferences: random 4-d features, an SIModel
    (hidden 64, 32), a truth uniform in the range, 99 preferences (R3's scale), the learner's own queries,
    mean of 8 seeds (standard errors 0.02-0.09). 'uniform': candidates uniform over Phi; 'belief':
    drawn from a pretrained SI's belief, so concentrated near the truth and harder to tell apart.

        precision at 10 / 20 / 30 % noise
        schedule      height uniform    height belief     mass uniform      mass belief
        reset/step    .40  .51  .46     .18  .29  .35     .53  .57  .46     .31  .35  .35
        t = 1         .55  .59  .52     .26  .33  .39     .59  .64  .51     .28  .36  .40
        t = 5         .55  .60  .50     .34  .38  .42     .70  .70  .53     .47  .49  .46
        t = 10        .59  .64  .51     .38  .42  .41     .66  .70  .53     .52  .51  .48
        t = 20        .59  .66  .54     .42  .44  .42     .67  .71  .57     .61  .55  .50
        t = 40        .59  .67  .53     .51  .48  .45     .64  .70  .54     .66  .60  .50

        recall at 10 / 20 / 30 % noise, over all SI updates (over the co-teaching updates only)
        reset/step    .39  .39  .43     .17  .21  .31     .42  .44  .44     .22  .26  .32
        t = 10        .54  .47  .46     .35  .30  .36     .44  .46  .44     .34  .33  .38
                     (.60  .52  .51)   (.39  .34  .40)   (.57  .59  .55)   (.44  .42  .48)

    With uniform candidates t = 10 is on the plateau (within a standard error of t = 20 and 40) in both
    domains; with belief-drawn candidates precision still rises up to t = 40 (+0.05 to +0.14 over t = 10).
    t = 10 is the smallest t near the plateau of the default query sampling, at about 14 ms per preference
    (1.3 ms per classifier step on the shared 2-core machine; PESI's own update takes 0.8 ms). A filter
    that forgets at random has the noise rate as precision: the reset-every-step schedule comes within
    0.1 of it for height with concentrated candidates, and is better than chance but below t >= 10
    elsewhere (all rows use the centred inputs of `classifier_inputs`).

    The forget-rate ramp (`ramp_steps`, `ramp_origin`), measured at t = 20 with 4 seeds: 0 steps, 10 from
    each refresh and 10 from the first step agree within 0.04 in precision and recall; 80 or 160 steps
    from each refresh raise precision by up to 0.1 and lower recall by up to 0.15, as the SI updates early
    in each refresh period then forget less. The default keeps Han et al.'s 10, counted in classifier
    steps and restarted with every fresh network.
    """

    classifier_learning_rate: Annotated[float, Range(1e-8, 1.0)] = 1e-2
    """Adam step size of the co-teaching classifiers M_0, M_1 (Table 2)."""
    classifier_hidden_sizes: NonEmptyTuple[Annotated[int, Integer(1)]] = (64, 64)
    """Hidden layer widths of M_0 and M_1, ReLU activations (Table 2)."""
    refresh_frequency: Annotated[int, Integer(1)] = 16
    """f_refresh: M_0 and M_1 are re-initialised each time the counted quantity (`refresh_unit`) reaches a
    multiple of this (Alg. 1 l.6-7; Table 2: 16 for height, 32 for mass), so they never run long enough
    to memorise the noise."""
    refresh_unit: Annotated[str, OneOf(REFRESH_UNITS)] = "preferences"
    """What f_refresh counts. 'preferences': |D|, the preferences received (Alg. 1 checks the frequency
    once per received preference, l.6); the classifiers are re-initialised before the co-teaching of the
    preference that brings |D| to a multiple of f_refresh, so they train for f_refresh * rounds steps
    between refreshes. 'steps': classifier co-teaching steps, the reset-every-step
    schedule (with rounds=1 a refresh every f_refresh steps of one minibatch each)."""
    rounds: Annotated[int, Integer(1)] = 10
    """t, 'Co-teaching Rounds' (Algorithm 1's input): classifier co-teaching steps (l.9-13) per received
    preference, before the one SI update on the last step's b_0. Chosen by measurement (class docstring)."""
    ramp_steps: Annotated[int, Integer(0)] = 10
    """Classifier steps over which the forget rate rises linearly from 0 to its final value (Han et al.
    ramp it over their first 10 epochs: a network fits clean data first, and an untrained network's
    losses say nothing about which labels are flipped). 0 forgets the full amount from the first step."""
    ramp_origin: Annotated[str, OneOf(RAMP_ORIGINS)] = "refresh"
    """'refresh': the ramp restarts at every (re-)initialisation, since each refresh starts an untrained
    network, as in Han et al. 'start': it runs once from the first co-teaching step (the reset-every-step
    schedule, where a restart would keep the forget rate low for most of each 16-step refresh period)."""
    update_before_start: bool = True
    """While |D| <= s, update SI by Eq. 2 on an unfiltered batch, as PESI does (True), or not at all (False,
    Alg. 1 l.5 read literally, the reset-every-step schedule). True keeps one SI update per preference, so
    CO-PESI and PESI make the same number of updates and differ only by the filter."""

    pairs_only = True

    SEQUENCES: ClassVar[tuple[str, ...]] = ("classifier_hidden_sizes",)
    """Layer widths, whose values may repeat (`check_fields`)."""

    def __post_init__(self) -> None:
        check_fields(self, self.SEQUENCES)

    def start(self, learner: SILearner) -> Filter:
        return CoTeachingFilter(learner, self)


def reset_every_step_schedule(**overrides: Any) -> CoTeaching:
    """The reset-every-step schedule: one classifier step per preference, a refresh every f_refresh such
    steps, the ramp from the first step only, and no SI update while |D| <= s; for the sensitivity study."""
    settings: dict[str, Any] = dict(
        refresh_unit="steps", rounds=1, ramp_origin="start", update_before_start=False
    )
    return CoTeaching(**{**settings, **overrides})


class CoTeachingFilter(UpdateLog):
    """Algorithm 1's running filter of one learner: the classifiers M_0, M_1 and their schedule.

    Every SI update is recorded (its batch and the forgotten entries), so the filter can be scored against
    the teacher's recorded flips (`precision_recall`); the learner itself never sees which labels were
    flipped.
    """

    def __init__(self, learner: SILearner, setting: CoTeaching) -> None:
        super().__init__(learner)
        self.setting = setting
        # Preferences whose learning step ran co-teaching (|D| > s), and classifier steps over all of them.
        self.coteaching_steps = 0
        self.classifier_steps = 0
        # |D| at each re-initialisation of M_0, M_1 (their construction is not counted).
        self.refreshed_at: list[int] = []
        self.pair = CoTeachingPair(
            setting.classifier_hidden_sizes, setting.classifier_learning_rate, learner.next_seed()
        )
        self._steps_since_refresh = 0
        self._refresh_period: int | None = None
        # Buffer indices of the most recent b_0 given to SI, kept for inspection.
        self.last_selection: np.ndarray | None = None

    def forget_rate(self, step: int, noise_level: float) -> float:
        """Han et al.'s schedule: a linear ramp from 0 to 1 - remember rate = noise_level (A.7) over
        `ramp_steps` classifier steps, `step` counting from the ramp's origin (`CoTeaching.ramp_origin`)."""
        ramp = 1.0 if self.setting.ramp_steps == 0 else min(1.0, step / self.setting.ramp_steps)
        remember_rate = 1.0 - noise_level
        return (1.0 - remember_rate) * ramp

    def forget_number(self, step: int, batch_size: int, noise_level: float) -> int:
        """n_forget for a batch, rounded half up, and always leaving at least one sample to learn from."""
        return min(math.floor(self.forget_rate(step, noise_level) * batch_size + 0.5), batch_size - 1)

    def _refresh(self) -> None:
        # Alg. 1 l.7: randomly initialise M_0 and M_1.
        self.pair.reinitialise(self.learner.next_seed())
        self.refreshed_at.append(len(self.learner))
        self._steps_since_refresh = 0

    def _refresh_by_preferences(self) -> None:
        # Alg. 1 l.6-7, f_refresh counted in preferences: re-initialise when |D| reaches a new multiple of
        # f_refresh. The classifiers start fresh, so the first co-teaching preference only notes the period.
        period = len(self.learner) // self.setting.refresh_frequency
        if self._refresh_period is not None and period != self._refresh_period:
            self._refresh()
        self._refresh_period = period

    def learn(self, rate: float) -> None:
        learner, setting = self.learner, self.setting
        # Alg. 1 l.5: the classifiers wait until the buffer holds more than s preferences.
        if len(learner) <= learner.start_size:
            if setting.update_before_start:
                self.warm_up(learner.sample_batch(), rate)
            return
        if setting.refresh_unit == "preferences":
            self._refresh_by_preferences()
        b0 = batch = np.empty(0, dtype=np.int64)
        for _ in range(setting.rounds):
            if (
                setting.refresh_unit == "steps"
                and self.classifier_steps > 0
                and self.classifier_steps % setting.refresh_frequency == 0
            ):
                self._refresh()
            # Alg. 1 l.9: sample batch b from D
            batch = learner.sample_batch()
            _, indices, labels = learner.batch_tensors(batch)
            pairs = classifier_inputs(learner.model.normalised_values[indices])
            targets = (labels[:, 0] < 0).long()  # y = 1 -> class 0, y = -1 -> class 1
            # Alg. 1 l.10-13: select b_0, b_1 and cross-update M_0, M_1
            ramp_step = (
                self._steps_since_refresh if setting.ramp_origin == "refresh" else self.classifier_steps
            )
            b0, _ = self.pair.step(pairs, targets, self.forget_number(ramp_step, len(batch), rate))
            self.classifier_steps += 1
            self._steps_since_refresh += 1
        # Alg. 1 l.14: update SI by Eq. 2 on the last b_0, once per preference as PESI does
        self.last_selection = batch[b0]
        self.record(batch, np.setdiff1d(batch, batch[b0]))
        learner.update_si(batch[b0], rate)
        self.coteaching_steps += 1
