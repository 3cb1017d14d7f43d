"""The two tasks of the study, and their registration with gymnasium.

Importing this package registers `hipref/DeskWiping-v0` and `hipref/Pushing-v0`, as gymnasium documents for
a package of environments: `import hipref.envs`, then `gymnasium.make("hipref/DeskWiping-v0")`; or, without
the import, `gymnasium.make("hipref.envs:hipref/DeskWiping-v0")`, which imports this package first. The
entry points are strings, so MuJoCo and the environments' classes load only when an environment is made.
`import hipref` alone registers nothing and loads no numerical library (a sweep worker imports it before it
limits those libraries to one thread).
"""

from __future__ import annotations

import gymnasium

ENVIRONMENTS: dict[str, str] = {
    "hipref/DeskWiping-v0": "hipref.envs.gym_envs:DeskWipingEnv",
    "hipref/Pushing-v0": "hipref.envs.gym_envs:PushingEnv",
}
"""Gymnasium id of each task and its entry point, imported only when an environment is made."""

for _env_id, _entry_point in ENVIRONMENTS.items():
    gymnasium.register(id=_env_id, entry_point=_entry_point)
