"""JAX's persistent compilation cache, so a (re)joining worker skips the compile."""

from __future__ import annotations

import os
from pathlib import Path

DEFAULT_DIR = Path(os.environ.get("PIZERO_COMPILE_CACHE", Path.home() / ".cache" / "pizero-ray" / "jax"))


def enable(directory: str | os.PathLike | None) -> None:
    """Turns the cache on in this process; ``None`` or "none" leaves it off."""
    if directory is None or str(directory).lower() == "none":
        return
    import jax

    path = Path(directory).expanduser().absolute()
    path.mkdir(parents=True, exist_ok=True)
    jax.config.update("jax_compilation_cache_dir", str(path))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
