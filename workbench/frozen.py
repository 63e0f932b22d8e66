"""Read-only arrays for frozen results: a frozen dataclass is only immutable if the arrays it holds are."""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["readonly"]


def readonly(a: Any) -> Any:
    """A float64 copy of ``a`` with writing switched off; ``None`` stays ``None``."""
    if a is None:
        return None
    out = np.array(a, dtype=np.float64, copy=True)
    out.setflags(write=False)
    return out
