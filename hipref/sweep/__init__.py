"""The study's one way to run a grid of runs: cells in parallel, each cached as soon as it finishes.

A *cell* is a frozen dataclass config that carries its own seed; a *cell function* is a module-level
function `fn(cell) -> pandas.DataFrame` of tidy rows. `run_sweep` runs the cells on local worker
processes (all cores by default) or, given a scheduler address, on a Dask cluster, and returns their
rows in the order of the cells. Because every cell seeds itself and runs on one thread, the rows are
byte-identical whichever backend and however many workers.

- `engine`: the local pool and the Dask client, and `run_sweep` over them.
- `cache`: the keys (`cell_key`, `code_version`), the cells' and artefacts' entries (`cached_artefact`,
  `cached_prefix`), their copies in memory and the directory the running sweep caches in.
- `entries`: an entry on disk (`write_entry`, `read_entry`), carrying its key and a checksum that must
  match before it is used, and the check that a cache directory can be written.
- `progress`: a sweep's progress, a tqdm bar on a terminal or one line updated in place in a notebook.

Only the standard library (and tqdm) is imported at load time: a spawned worker imports this package
before numpy or torch are loaded, so their one-thread settings take effect.
"""

from hipref.sweep.cache import (
    NO_CACHE,
    CacheDir,
    Expect,
    artefacts_in,
    cached_artefact,
    cached_prefix,
    cell_key,
    code_version,
    default_cache_dir,
    forget_artefacts,
)
from hipref.sweep.engine import SweepError, run_sweep
from hipref.sweep.entries import read_entry, write_entry

__all__ = [
    "NO_CACHE",
    "CacheDir",
    "Expect",
    "SweepError",
    "artefacts_in",
    "cached_artefact",
    "cached_prefix",
    "cell_key",
    "code_version",
    "default_cache_dir",
    "forget_artefacts",
    "read_entry",
    "run_sweep",
    "write_entry",
]
