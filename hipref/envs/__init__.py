"""The two tasks of the study, and their registration with gymnasium.

`import hipref` (which imports this package) is enough for `gymnasium.make("hipref/DeskWiping-v0")` and
`gymnasium.make("hipref/Pushing-v0")`. The registration waits for gymnasium: it happens at once if gymnasium
is already loaded, else right after gymnasium's own import, through an import hook. So importing the
package loads neither gymnasium nor numpy nor MuJoCo, which a sweep worker needs: it imports `hipref`
before it limits the numerical libraries to one thread, a setting they read when they load.
"""

from __future__ import annotations

import contextlib
import sys
import warnings

TYPE_CHECKING = False  # as typing.TYPE_CHECKING, without importing typing at run time
if TYPE_CHECKING:
    from collections.abc import Sequence
    from importlib.machinery import ModuleSpec
    from types import ModuleType
    from typing import Any

ENVIRONMENTS: dict[str, str] = {
    "hipref/DeskWiping-v0": "hipref.envs.gym_envs:DeskWipingEnv",
    "hipref/Pushing-v0": "hipref.envs.gym_envs:PushingEnv",
}
"""Gymnasium id of each task and its entry point, imported only when an environment is made."""


def register_environments() -> None:
    """Register the tasks with gymnasium (importing it); a no-op for those already registered."""
    import gymnasium

    for env_id, entry_point in ENVIRONMENTS.items():
        if env_id not in gymnasium.registry:
            gymnasium.register(id=env_id, entry_point=entry_point)


class _RegisterAfterImport:
    """gymnasium's own loader, followed by the registration of the tasks (an importlib loader; the
    abstract base classes of `importlib.abc` are not imported, as they load `importlib.resources`)."""

    def __init__(self, loader: Any, hook: _GymnasiumHook) -> None:
        self.loader = loader
        self.hook = hook

    def create_module(self, spec: ModuleSpec) -> ModuleType | None:
        return self.loader.create_module(spec)

    def exec_module(self, module: ModuleType) -> None:
        # gymnasium sees its own loader, during its import and after.
        module.__loader__ = self.loader
        if module.__spec__ is not None:
            module.__spec__.loader = self.loader
        self.loader.exec_module(module)
        with contextlib.suppress(ValueError):
            sys.meta_path.remove(self.hook)
        try:
            register_environments()
        except Exception as error:  # a failed registration must not fail the user's `import gymnasium`
            warnings.warn(
                f"hipref could not register its gymnasium environments ({error!r}); "
                "call hipref.envs.register_environments() to see why",
                stacklevel=2,
            )


class _GymnasiumHook:
    """An importlib meta path finder: it finds gymnasium through the other finders and wraps its loader
    in `_RegisterAfterImport`.

    It stays in `sys.meta_path` until gymnasium has been imported, so a mere `importlib.util.find_spec`
    (which loads nothing) does not use it up."""

    def find_spec(
        self, fullname: str, path: Sequence[str] | None, target: ModuleType | None = None
    ) -> ModuleSpec | None:
        if fullname != "gymnasium":
            return None
        for finder in sys.meta_path:
            find = getattr(finder, "find_spec", None)
            if finder is self or find is None:
                continue
            spec = find(fullname, path, target)
            if spec is not None:
                if spec.loader is not None and hasattr(spec.loader, "exec_module"):
                    spec.loader = _RegisterAfterImport(spec.loader, self)
                return spec
        return None


if "gymnasium" in sys.modules:
    register_environments()
elif not any(isinstance(finder, _GymnasiumHook) for finder in sys.meta_path):
    sys.meta_path.insert(0, _GymnasiumHook())
