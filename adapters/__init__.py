"""Adapters: flight and teleoperation logs in, :class:`~workbench.data.demonstrations.DemonstrationSet` out (and back).

Each format's reader turns a file into *streams* (:mod:`adapters.streams`): per message type or topic, a time
column and field columns. Everything after that is shared: a *mapping* (:mod:`adapters.mapping`, TOML files in
``adapters/mappings/``) picks the state and input channels, the *aligner* (:mod:`adapters.align`) puts them
on a uniform ``dt`` grid, the *segmenter* (:mod:`adapters.segment`) cuts the result into demonstrations.

>>> import adapters
>>> streams = adapters.read_streams("flight.tlog")                      # doctest: +SKIP
>>> ds = adapters.load("flight.tlog", mapping="ardupilot_manual")       # doctest: +SKIP
>>> print(adapters.inspect("flight.tlog"))                              # doctest: +SKIP

Formats: each declared by its own module in ``adapters/formats/declared/`` (:mod:`adapters.formats`), recognised by
their first bytes.
"""

from __future__ import annotations

import importlib
import importlib.util
import os
from collections.abc import Iterable
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import pandas as pd

    from adapters.formats import FORMATS, Format, detect_format
    from adapters.mapping import ChannelMapping, load_mapping, shipped_mappings
    from adapters.pipeline import build
    from adapters.streams import Streams
    from adapters.summary import LogSummary
    from adapters.writer import demo_streams, write
    from workbench.data.demonstrations import DemonstrationSet

# The names below load their module (and numpy, pandas, pyarrow behind it) on first use, so that importing
# the package, or a command that never reads a log, starts fast.
_LAZY = {
    "FORMATS": "adapters.formats",
    "Format": "adapters.formats",
    "detect_format": "adapters.formats",
    "get_format": "adapters.formats",
    "ChannelMapping": "adapters.mapping",
    "load_mapping": "adapters.mapping",
    "shipped_mappings": "adapters.mapping",
    "build": "adapters.pipeline",
    "Streams": "adapters.streams",
    "LogSummary": "adapters.summary",
    "summarize": "adapters.summary",
    "demo_streams": "adapters.writer",
    "write": "adapters.writer",
}


def __getattr__(name: str):
    if name in _LAZY:
        value = getattr(importlib.import_module(_LAZY[name]), name)
        globals()[name] = value
        return value
    if not name.startswith("_") and importlib.util.find_spec(f"adapters.{name}") is not None:
        return importlib.import_module(f"adapters.{name}")  # a submodule, as when the package imported them all
    raise AttributeError(f"module 'adapters' has no attribute {name!r}")


__all__ = [
    "FORMATS",
    "Format",
    "Streams",
    "ChannelMapping",
    "LogSummary",
    "detect_format",
    "read",
    "read_streams",
    "load",
    "build",
    "inspect",
    "write",
    "demo_streams",
    "load_mapping",
    "shipped_mappings",
    "choose_mapping",
]


def _format(path: str | os.PathLike, format: str | None) -> Format:
    from adapters.formats import detect_format, get_format
    from workbench.atomic import refuse_special_file

    refuse_special_file(path)  # before any reader opens it: a FIFO would block the open itself
    return get_format(format) if format is not None else detect_format(path)


def read(path: str | os.PathLike, topics: Iterable[str] | None = None, *, format: str | None = None) -> Streams:
    """Read a log into :class:`Streams` (streams + what was skipped + per-stream counts).

    Parameters
    ----------
    path : path-like
        The log; its format is recognised from its first bytes unless ``format`` names it.
    topics : iterable of str, optional
        Stream names to read (message types, topics); all by default.
    """
    fmt = _format(path, format)
    return fmt.read(path, None if topics is None else list(topics))


def read_streams(path: str | os.PathLike, topics: Iterable[str] | None = None) -> dict[str, pd.DataFrame]:
    """A log's streams: stream name (``"ATTITUDE"``, ``"/topic"``) -> DataFrame with a float64 ``t`` (seconds)
    and one column per field; only ``topics`` where given (stream names: MAVLink message types, topics)."""
    return dict(read(path, topics).frames)


def load(
    path: str | os.PathLike,
    mapping: str | os.PathLike | ChannelMapping | None = None,
    *,
    format: str | None = None,
    allow_still: bool = False,
) -> DemonstrationSet:
    """Load a log as demonstrations with a mapping (a shipped name, a TOML path, or a ChannelMapping; by default
    the one :func:`choose_mapping` chooses).

    A position or velocity that never moves in the whole log (no GPS), an estimated velocity that does not follow
    the log's GPS velocity (the mapping's ``[reference]``) or a log without the GPS stream the mapping says is always
    logged (dead reckoning) is an error naming it, unless ``allow_still`` (for looking at the log: the cause is then
    in each demonstration's ``meta["still"]``). A segment is cut where the vehicle flipped (``meta["flipped"]``).

    Only the streams the mapping names are read. Each demonstration's ``meta`` has ``id``, ``source``,
    ``format``, ``mapping``, ``t0`` (its start on the log clock), ``skipped`` (counts by cause for the file)
    and, where the log carries them, ``label``, ``subject``, ``target``, ``success``, ``mode``.

    Raises
    ------
    FormatError
        Unknown format (the message lists the known ones).
    MappingError
        The mapping is invalid or names a stream or field the log lacks (listing the nearest it has).
    DataError
        The file is damaged beyond reading, or holds no demonstration under the mapping's rules.
    """
    from adapters.mapping import MappingError, load_mapping
    from adapters.pipeline import build
    from adapters.streams import damaged_regions
    from adapters.summary import VEHICLE_STREAMS
    from workbench.errors import DataError

    fmt = _format(path, format)
    if mapping is None:  # the shipped mapping made for the vehicle the log names (choose_mapping)
        mapping = choose_mapping(path, format=fmt.name)[0]
    m = load_mapping(mapping).for_format(fmt.name)
    try:
        m.check_complete()
    except MappingError as e:  # the log's format (found from its content, maybe not its suffix) is half the cause
        raise MappingError(f"{path}: read as a {fmt.name} log: {e}") from None
    # the vehicle's own streams too, so that a mapping made for another vehicle is refused by name
    streams = fmt.read(path, [*m.stream_candidates(), *VEHICLE_STREAMS])
    try:
        return build(streams, m, allow_still=allow_still)
    except DataError as exc:
        # a format without a checksum (DataFlash) reads damaged values that still parse as data: a stop on them
        # (a stick that does not move with its setpoint, a velocity off the GPS's) is the damage's, not the flight's
        if not (damage := damaged_regions(streams)):
            raise
        cause = str(exc).removeprefix(f"{streams.path}: ")
        raise DataError(f"{path}: damaged log, {damage} (the {fmt.name} format has no checksum: damaged values "
                        f"that still parse are read as data, so what the import then stopped on may be the "
                        f"damage's): {cause}") from None


def choose_mapping(path: str | os.PathLike, *, format: str | None = None) -> tuple[str, str]:
    """The shipped mapping for the vehicle a log names, and why: ``("ardupilot_manual", "made for ArduCopter
    V3.3-dev")``; ``planar_quadrotor`` (the simulator's and the testbed's logs) where the log names no vehicle a
    shipped mapping is made for."""
    from adapters.mapping import MappingError, load_mapping, mapping_for_vehicle
    from adapters.selection import resolve_channel, select
    from adapters.summary import VEHICLE_STREAMS, log_vehicle
    from adapters.transforms import TRANSFORMS

    fmt = _format(path, format)
    own = load_mapping("planar_quadrotor").for_format(fmt.name)
    streams = fmt.read(path, [*own.stream_candidates(), *VEHICLE_STREAMS])
    try:  # the workbench's own recordings (simulator, testbed) carry every channel of its own layout
        for ch in own.channels:
            v = resolve_channel(ch, streams)
            select(v.selector, streams, "", "", n_columns=TRANSFORMS[v.transform].n_columns)
        if own.channels:
            return "planar_quadrotor", "the workbench's own layout: every channel of it is in the log"
    except MappingError:
        pass
    vehicle, table = log_vehicle(streams)
    name = mapping_for_vehicle(fmt.name, table)
    if name is None:
        why = f"no shipped mapping is made for {vehicle}" if vehicle else "the log names no vehicle"
        return "planar_quadrotor", why
    return name, f"made for {vehicle or table}"


def inspect(path: str | os.PathLike, *, format: str | None = None) -> LogSummary:
    """What a log holds: streams with counts, rates, fields and time spans; flight modes; skipped data."""
    from adapters.summary import summarize

    return summarize(read(path, format=format))
