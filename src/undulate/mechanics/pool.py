"""The threads that evaluate element groups side by side (shared by the assembly and the
mixed merit)."""

from __future__ import annotations

import functools
import os
from concurrent.futures import ThreadPoolExecutor

__all__ = ["pool"]


@functools.cache
def pool() -> ThreadPoolExecutor:
    """Threads that evaluate element groups concurrently (2 at most: the kernels themselves
    use XLA's threads too; on the 2-core machine the demo's assembly went 33 -> 27 ms)."""
    return ThreadPoolExecutor(max_workers=max(1, min(2, os.cpu_count() or 1)),
                              thread_name_prefix="undulate-assembly")
