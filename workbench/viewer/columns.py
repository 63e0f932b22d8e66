"""The one path every bulk send of the viewer goes through, so no chunk without rows reaches a recording.

The rerun 0.41 viewer panics in its time panel (``AbsoluteTimeRange { min: TimeInt::MIN, max: TimeInt::MAX }``)
when one timeline holds two chunks without rows, e.g. the outliers of a trial that has none; ``rerun rrd verify``
passes on such a file, so the guard has to be in the writer.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import rerun as rr

__all__ = ["n_rows", "send_columns"]


def n_rows(indexes: Sequence[rr.TimeColumn]) -> int:
    """Rows of a send: the length of its index columns (every column of one send has as many)."""
    if not indexes:
        return 0
    return min(len(col.as_arrow_array()) for col in indexes)


def send_columns(rec: rr.RecordingStream, path: str, indexes: Sequence[rr.TimeColumn], columns: Any) -> bool:
    """``rec.send_columns`` unless the send has no rows; returns whether anything was sent.

    Parameters
    ----------
    rec : rerun.RecordingStream
    path : str
        Entity path.
    indexes : sequence of rerun.TimeColumn
        The time columns; a send whose index is empty is dropped.
    columns : rerun column batches
        As for :meth:`rerun.RecordingStream.send_columns`.
    """
    if n_rows(indexes) == 0:
        return False
    rec.send_columns(path, indexes=list(indexes), columns=columns)
    return True
