"""Clocks: which time a sample of a stream is put at.

Every stream carries ``t``, the log's own clock: for a tlog the ground station's *arrival* time (UNIX
seconds), for MCAP ``log_time``, for ULog the autopilot's ``timestamp`` (µs since boot), for CSV the ``t``
column. All streams of a file share that clock, so mapping channels from several streams is consistent.

Arrival time is not sample time. Over a telemetry radio, messages are sent in bursts and queued, so arrival
times jitter by tens of milliseconds and bunch up; MAVLink messages also carry the autopilot's own sample
time (``time_boot_ms``, ``time_usec``), which is exact but restarts at every reboot and is absent from some
messages (``HEARTBEAT``). A mapping picks explicitly (``clock = …``):

* ``clock = "log"`` (default): ``t`` as the reader gives it.
* ``clock = { field = "time_boot_ms", scale = 0.001 }``: for streams with that field, the sample spacing
  comes from the vehicle clock and the position on the log clock: within each *boot epoch* (a run in which
  the field does not decrease) ``t = field * scale + median(t_log - field * scale)``. Streams without the
  field (HEARTBEAT, STATUSTEXT) stay on the log clock, which is the clock the anchoring puts everything on,
  so mode changes and samples still line up to within the link latency's spread.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from adapters.streams import numeric

if TYPE_CHECKING:
    import pandas as pd

    from adapters.rules import ClockSpec

__all__ = ["stream_times"]


def stream_times(spec: ClockSpec, frame: pd.DataFrame) -> np.ndarray:
    """The time of every row of ``frame`` under clock ``spec`` (float64 seconds)."""
    t_log = frame["t"].to_numpy(dtype=np.float64, na_value=np.nan)
    if spec.field is None or spec.field not in frame.columns or len(frame) == 0:
        return t_log
    vehicle = numeric(frame, spec.field) * spec.scale
    out = t_log.copy()
    resets = np.flatnonzero(np.diff(vehicle) < 0) + 1
    for rows in np.split(np.arange(len(frame)), resets):
        lag = t_log[rows] - vehicle[rows]
        lag = lag[np.isfinite(lag)]
        if lag.size:
            out[rows] = vehicle[rows] + np.median(lag)
    return out
