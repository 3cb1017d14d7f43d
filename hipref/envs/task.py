"""What a study needs of a world whose one physical parameter phi is unknown, whichever the world.

Both tasks (`hipref.envs.wiping.WipingTask`, `hipref.envs.pushing.PushingTask`) implement `Task`: the range
of phi, a random layout of an episode, a rollout of the goal-conditioned low-level policy pi^l (analytic or
learned, `hipref.envs.low_level`) given an estimate of phi in a world whose phi is the truth, and the
analytic pi^l's demonstrations a learned one imitates. What SI sees of a rollout, a slice tau of h control
periods (`clip`, `probe_slice`), is built here on that interface alone.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple, Protocol

import numpy as np

from hipref.envs.low_level import Demonstration, Perturb

ROUTES: tuple[str, ...] = ("both", "input", "path")
"""How an estimate reaches a learned pi^l: as its input and through the path it follows ('both', what an
estimate does), as the input alone (the path the truth's), or through the path alone (the input the
truth)."""

Layout = tuple[np.ndarray, np.ndarray]
"""An episode's layout on the desk: the stroke's start and goal (wiping), the cube's start and goal
(pushing)."""


class Rollout(NamedTuple):
    """One execution of pi^l."""

    features: np.ndarray
    """(periods, FEATURES_PER_PERIOD): what SI sees of each control period (`hipref.control.tool`)."""
    success: bool
    """Whether the task succeeded."""


class Task(Protocol):
    """A world with one unknown parameter and its goal-conditioned low-level policy pi^l."""

    @property
    def parameter_range(self) -> tuple[float, float]:
        """The range phi (and every estimate of it) lies in."""
        ...

    def sample_layout(self, rng: np.random.Generator) -> Layout:
        """A random layout of an episode."""
        ...

    def planned_periods(self, layout: Layout) -> int | None:
        """The length in control periods of every rollout from `layout` when the layout alone sets it (then
        `rollout` can stop early), else None."""
        ...

    def rollout(
        self, true_parameter: float, estimate: float, layout: Layout, periods: int | None = None
    ) -> Rollout:
        """Execute pi^l with `estimate` from `layout` in a world whose parameter is `true_parameter`; only
        the first `periods` control periods (bit for bit the whole rollout's) where `planned_periods` is
        not None."""
        ...

    def clip_frames(
        self, true_parameter: float, estimate: float, layout: Layout, frames: int = 40
    ) -> list[np.ndarray] | None:
        """The clip of `rollout` as `frames` images evenly spaced over it (`hipref.sim.render`), seen from
        where the effect of a wrong estimate shows; None where no GL is."""
        ...

    def episode_metrics(
        self, true_parameter: float, estimate: float, layout: Layout, route: str = "both"
    ) -> dict[str, float]:
        """One rollout as a study shows it: its success (`success_rate`) and the domain's measures of how
        it went. `route` is how the estimate reaches a learned pi^l (`ROUTES`); a task whose pi^l takes
        the estimate only as input refuses all but 'both'."""
        ...

    @property
    def control_period(self) -> float:
        """Seconds between two of pi^l's joint references."""
        ...

    @property
    def goal_size(self) -> int:
        """Values of the goal g a learned pi^l is conditioned on (`hipref.envs.low_level`)."""
        ...

    def demonstrate(
        self, true_parameter: float, layout: Layout, perturb: Perturb, estimate: float | None = None
    ) -> Demonstration:
        """The analytic pi^l, told `estimate` (None: the true parameter), executing the layout in a world
        at `true_parameter`: Algorithm 3's expert P, SPD tracking its reference plus `perturb`'s; labelled
        with the parameter P was told."""
        ...


class Clip(NamedTuple):
    """What a query observes of the clip pi^l executes with one candidate: its slice tau."""

    estimate: float
    """The candidate pi^l was given."""
    periods: int
    """The clip's length in control periods, over which the slice's place was drawn."""
    first: int
    """The slice's first period."""
    tau: np.ndarray
    """The slice, flattened (the SI input)."""

    def replay(self, estimate: float, history: int, rng: np.random.Generator) -> np.ndarray:
        """tau again, drawing the slice's place from `rng` as the execution did, without the physics."""
        first = slice_start(self.periods, history, rng)
        if estimate != self.estimate or first != self.first:
            raise RuntimeError(
                f"a replayed clip was asked for estimate {estimate} at period {first}, but was executed "
                f"with {self.estimate} at {self.first}: the queries depend on what the learner has learnt"
            )
        return self.tau

    def replayer(self, history: int) -> Observe:
        """`replay` as the `observe` a learner's `ask` calls."""
        return lambda estimate, rng: self.replay(estimate, history, rng)


Observe = Callable[[float, np.random.Generator], np.ndarray]
"""What a learner's `ask` calls for tau: the slice of the clip pi^l executes with a candidate phi, its place
drawn with the rng given."""


def evenly_spaced(periods: int, frames: int) -> np.ndarray:
    """Indices of `frames` control periods evenly spaced over a clip of `periods` (repeated when the clip
    is shorter): a clip is shown as a fixed number of frames, however long it ran."""
    return np.linspace(0, periods - 1, frames).round().astype(int)


def slice_start(periods: int, history: int, rng: np.random.Generator) -> int:
    """Where a slice of h periods starts, uniformly over a clip of `periods` periods."""
    if periods < history:
        raise ValueError(f"a clip of {periods} periods is shorter than the slice length h = {history}")
    return int(rng.integers(0, periods - history + 1))


def clip(
    task: Task,
    true_parameter: float,
    estimate: float,
    layout: Layout,
    history: int,
    rng: np.random.Generator,
) -> Clip:
    """tau: h consecutive periods at a place drawn uniformly with `rng` of the clip pi^l executes with
    `estimate` from `layout`, flattened (the SI input).

    Where the layout alone sets the clip's length (wiping: the stroke's distance at the tool speed), only
    the periods up to tau's end are simulated; physics draws no random numbers, so they are the whole
    clip's, bit for bit. Otherwise (a push ends when the cube comes to rest) the clip is executed whole.
    """
    periods = task.planned_periods(layout)
    if periods is None:
        features = task.rollout(true_parameter, estimate, layout).features
        periods = len(features)
        first = slice_start(periods, history, rng)
    else:
        first = slice_start(periods, history, rng)
        features = task.rollout(true_parameter, estimate, layout, periods=first + history).features
    return Clip(estimate, periods, first, features[first : first + history].reshape(-1))


def observer(
    task: Task, true_parameter: float, layout: Layout, history: int, executed: list[Clip] | None = None
) -> Observe:
    """`clip`'s tau as the `observe` a learner's `ask` calls, every candidate from `layout`; each clip
    executed is appended to `executed` when given (to be replayed later)."""

    def observe(estimate: float, rng: np.random.Generator) -> np.ndarray:
        executed_clip = clip(task, true_parameter, estimate, layout, history, rng)
        if executed is not None:
            executed.append(executed_clip)
        return executed_clip.tau

    return observe


def random_estimate(task: Task, rng: np.random.Generator) -> float:
    """A uniformly random estimate: what probing rollouts (and Algorithm 4's data) run with."""
    low, high = task.parameter_range
    return float(rng.uniform(low, high))


def probe_slice(task: Task, true_parameter: float, history: int, rng: np.random.Generator) -> np.ndarray:
    """tau of a probing rollout: pi^l executed with a uniformly random estimate from a random layout."""
    estimate = random_estimate(task, rng)
    return clip(task, true_parameter, estimate, task.sample_layout(rng), history, rng).tau
