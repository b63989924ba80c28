"""JAX's persistent compilation cache for jaxskin's commands and cluster workers.

A command compiles each static configuration of a scene once; kept on disk, the next run
(or a worker that restarts) loads the program instead of compiling it again. The cache
lives in `$JAXSKIN_CACHE_DIR`, else `$XDG_CACHE_HOME/jaxskin/jax` (`~/.cache/jaxskin/jax`);
`JAXSKIN_NO_COMPILE_CACHE=1` switches it off.
"""

from __future__ import annotations

import os

__all__ = ["enable"]


def enable() -> None:
    """Persist compiled programs across runs (JAXSKIN_NO_COMPILE_CACHE=1 switches it off).
    A folder that cannot be made is no reason to fail: the programs are compiled again."""
    if os.environ.get("JAXSKIN_NO_COMPILE_CACHE", "") not in ("", "0"):
        return
    import jax

    root = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    path = os.environ.get("JAXSKIN_CACHE_DIR") or os.path.join(root, "jaxskin", "jax")
    try:
        os.makedirs(path, exist_ok=True)
    except OSError:
        return
    jax.config.update("jax_compilation_cache_dir", path)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", -1)
