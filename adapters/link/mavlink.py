"""A live MAVLink link: bytes or pymavlink messages in, clean time-stamped samples out; and a tlog sent as a link.

:class:`MavlinkReader` is what stands between a radio (or a UDP port) and :class:`adapters.link.online.OnlineAligner`:

* **parsing** — pymavlink's own parser (the ``v20`` dialect module :mod:`adapters.formats.mavlink_dialect` loads) with
  robust parsing: garbage bytes and frames whose checksum fails are skipped and counted, never decoded. A UDP
  datagram is a whole number of frames, so a frame cut off at a datagram's end is counted as truncated and
  the parser starts clean on the next datagram (on a byte stream — TCP, serial — the parser just waits for
  the rest);
* **sources** — one vehicle: the system given, else the first system that sends a mapped message or a vehicle
  HEARTBEAT; within it, per message type, the first component (offline import keeps the most frequent source
  per stream). Messages of other systems and components are counted and dropped;
* **duplicates and order** — a frame seen before (same source, sequence number, message id and checksum,
  among the last 64 of its source) is dropped and counted; a frame whose sequence number is behind the
  latest is counted as out of order (its own time decides whether it is still used);
* **clock** — samples are stamped with the *vehicle's* clock: the message's ``time_boot_ms`` (or the
  mapping's clock field) where it has one; a message without one (MANUAL_CONTROL, HEARTBEAT, STATUSTEXT) is
  stamped with the latest vehicle time, the way a tlog stamps everything on arrival. Arrival times jitter
  and bunch over a radio (and scale with a replay's speed); the vehicle's clock does not, so grid steps
  land on the samples as they do offline. A clock that jumps back by more than ``reset_after`` seconds is a
  reboot: counted, and the aligner is told to start over. ``clock="arrival"`` stamps with the wall clock.

:func:`send_tlog` is the other end: a recorded tlog's raw frames sent to a link with their original timing,
scaled by a speed factor — a stand-in vehicle, like MAVProxy's log replay.
"""

from __future__ import annotations

import errno
import math
import os
import socket
import time
from collections import Counter, deque
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from adapters.formats.mavlink_dialect import load_dialect
from adapters.link.online import Sample
from workbench.errors import DataError, FormatError, WorkbenchError

__all__ = ["LinkError", "MavlinkReader", "Link", "open_link", "dialect_streams", "tlog_frames", "send_tlog",
           "SendReport"]

_RECENT = 64
_RECEIVE_BUFFER = 4 << 20
_BATCH = 512
_CHUNK = 65536
_PENDING = 4096


class LinkError(WorkbenchError, OSError):
    """A link cannot be opened or read (a bad connection string, a port in use, a missing serial device)."""


def dialect_streams(dialect: str = "ardupilotmega") -> dict[str, tuple[str, ...]]:
    """Every message of a dialect with its columns, named as the tlog reader names them (+ sysid, compid)."""
    d = load_dialect(dialect)
    return {name: (*lay.columns, "sysid", "compid") for name, lay in d.by_name.items()}


def _getters(dialect: str, stream: str) -> list[tuple[str, str, int | None]]:
    """(column, attribute, element index) for every column of a message type."""
    lay = load_dialect(dialect).by_name[stream]
    out = []
    for f in lay.fields:
        if f.is_array:
            out += [(c, f.name, i) for i, c in enumerate(f.columns)]
        else:
            out.append((f.columns[0], f.name, None))
    return out


class MavlinkReader:
    """MAVLink bytes (or pymavlink messages) → :class:`~adapters.link.online.Sample` of one vehicle, on its clock.

    Parameters
    ----------
    streams : collection of str
        Message types to turn into samples (those a mapping reads); the others are only counted.
    required : sequence of sets of str, optional
        What a system must send before it is followed: from each set (alternatives) one message type; default
        every type of ``streams``. Until a system has, its samples are held back (bounded), so a stray vehicle
        or a ground station sending a few of the same messages first is never mistaken for the one flown.
    system, component : int, optional
        Accept only this system (and component); default: the first system that sends what ``required`` names,
        and per message type its first component.
    clock : {"vehicle", "arrival"}
        Stamp samples with the vehicle's clock (default) or with the arrival (wall-clock) time.
    clock_field, clock_scale : str, float
        The vehicle's time field and its unit in seconds (``time_boot_ms``, 0.001).
    reset_after : float
        A vehicle clock going back by more than this many seconds is a reboot.
    dialect : str
        The pymavlink dialect (``ardupilotmega`` reads common messages too).

    Attributes
    ----------
    counts : Counter
        Everything the link brought, by cause: ``messages``, ``samples``, ``garbage bytes``, ``CRC failures``,
        ``truncated frames``, ``duplicates``, ``out of order``, ``other systems``, ``other components``,
        ``unknown messages``, ``clock resets``, ``shed (backlog)``; messages held while no vehicle is locked
        are :attr:`held`.
    received : Counter
        Every valid message by type, from any system, before and after the lock: what did arrive, even when
        no vehicle ever sent everything ``required`` names.
    system : int or None
        The vehicle locked onto.
    reset : bool
        Set when the vehicle clock restarted since the caller last cleared it.
    """

    def __init__(self, streams, *, required=None, system: int | None = None, component: int | None = None,
                 clock: str = "vehicle", clock_field: str = "time_boot_ms", clock_scale: float = 1e-3,
                 reset_after: float = 10.0, dialect: str = "ardupilotmega") -> None:
        if clock not in ("vehicle", "arrival"):
            raise WorkbenchError(f"clock must be 'vehicle' or 'arrival', got {clock!r}")
        self.dialect = dialect
        self._module = load_dialect(dialect).module
        self._parser = self._new_parser()
        self._streams = set(streams)
        self._getters = {s: _getters(dialect, s) for s in self._streams if s in load_dialect(dialect).by_name}
        self.system = system
        self.component = component
        self._required = [set(r) for r in required] if required is not None else [{x} for x in self._streams]
        self._sources: dict[int, _Source] = {}
        self.clock = clock
        self.clock_field, self.clock_scale = clock_field, float(clock_scale)
        self.reset_after = float(reset_after)
        self.counts: Counter = Counter()
        self.received: Counter = Counter()
        self.reset = False
        ids = load_dialect(dialect).by_name
        # the message ids worth parsing when behind: what the mapping reads, and what a lock needs
        self._wanted_ids = {ids[s].msgid for s in self._streams | {"HEARTBEAT"} if s in ids}
        self._seq: dict[tuple[int, int], int] = {}
        self._recent: dict[tuple[int, int], deque] = {}

    def _new_parser(self):
        parser = self._module.MAVLink(None)
        parser.robust_parsing = True
        return parser

    # -- bytes -----------------------------------------------------------------------------------------------
    def feed(self, data: bytes, arrival: float, *, datagram: bool = True) -> list[Sample]:
        """Parse received bytes (one UDP datagram, or a chunk of a byte stream); return the samples they give."""
        try:
            msgs = self._parser.parse_buffer(bytes(data)) or []
        except Exception:  # pymavlink raises on a few malformed inputs even when parsing robustly
            self.counts["undecodable frames"] += 1
            self._parser = self._new_parser()
            return []
        if datagram and self._parser.buf_len() > 0:
            self.counts["truncated frames"] += 1
            self._parser = self._new_parser()
        out: list[Sample] = []
        for msg in msgs:
            out += self.message(msg, arrival)
        return out

    # -- messages --------------------------------------------------------------------------------------------
    def message(self, msg: Any, arrival: float | None = None) -> list[Sample]:
        """One pymavlink message → samples (none, or several when untimed ones waited for the vehicle clock)."""
        arrival = time.time() if arrival is None else float(arrival)
        kind = msg.get_type()
        if kind == "BAD_DATA":
            reason = str(getattr(msg, "reason", "")).lower()
            if "crc" in reason:
                self.counts["CRC failures"] += 1
            else:
                self.counts["garbage bytes"] += len(getattr(msg, "data", b"") or b"")
            return []
        if kind.startswith("UNKNOWN_"):
            self.counts["unknown messages"] += 1
            return []
        self.received[kind] += 1
        src = (int(msg.get_srcSystem()), int(msg.get_srcComponent()))
        if self.system is not None and src[0] != self.system:
            self.counts["other systems"] += 1
            return []
        source = self._sources.setdefault(src[0], _Source())
        want = self.component if self.component is not None else source.components.setdefault(kind, src[1])
        if src[1] != want:
            self.counts["other components"] += 1
            return []
        if self._duplicate(msg, src):
            self.counts["duplicates"] += 1
            return []
        samples = self._samples(msg, kind, src, source, arrival)
        if self.system is None:  # not locked yet: hold this system's samples until it sends all the mapping reads
            source.seen.add(kind)
            source.n_messages += 1
            source.pending = [*source.pending[len(source.pending) + len(samples) - _PENDING:], *samples]
            if not all(need & source.seen for need in self._required):
                return []
            self.system = src[0]
            self.counts["messages"] += source.n_messages
            self.counts["other systems"] += sum(o.n_messages for k, o in self._sources.items() if k != src[0])
            self._sources = {src[0]: source}
            samples, source.pending = source.pending, []
            self.counts["samples"] += len(samples)
            return samples
        self.counts["messages"] += 1
        self.counts["samples"] += len(samples)
        return samples

    def _samples(self, msg: Any, kind: str, src: tuple[int, int], source: _Source, arrival: float) -> list[Sample]:
        t_own = self._own_time(msg)
        if t_own is not None:
            if t_own < source.vehicle_time - self.reset_after:
                source.vehicle_time = t_own
                source.pending = []
                if src[0] == self.system:
                    self.counts["clock resets"] += 1
                    self.reset = True
            elif t_own > source.vehicle_time:
                source.vehicle_time = t_own
        if kind not in self._getters:
            return []
        fields = {c: (getattr(msg, a)[i] if i is not None else getattr(msg, a)) for c, a, i in self._getters[kind]}
        fields["sysid"], fields["compid"] = src
        if self.clock == "arrival":
            return [Sample(kind, arrival, fields, arrival, True)]
        if t_own is not None:
            out = [Sample(k, t_own, f, a, False) for k, f, a in source.untimed]
            source.untimed = []
            return [*out, Sample(kind, t_own, fields, arrival, True)]
        if not math.isfinite(source.vehicle_time):  # no vehicle time yet: wait for the first one (bounded)
            source.untimed = [*source.untimed[-255:], (kind, fields, arrival)]
            return []
        return [Sample(kind, source.vehicle_time, fields, arrival, False)]

    @property
    def held(self) -> int:
        """Messages received from candidate vehicles while none is locked (each sent only part of what the
        mapping needs): counted here until a lock makes them the vehicle's ``messages`` or ``other systems``."""
        return 0 if self.system is not None else sum(s.n_messages for s in self._sources.values())

    def never_received(self) -> list[str]:
        """What ``required`` names that no system ever sent (alternatives joined by ``or``): why nothing locks."""
        missing = (" or ".join(sorted(need)) for need in self._required if not need & set(self.received))
        return list(dict.fromkeys(missing))  # a message several fields come from is named once

    def shed(self, data: bytes) -> bool:
        """Whether a datagram may be dropped unparsed when the link is behind: it is not a frame of a message
        the mapping reads (or a HEARTBEAT), judged from its header alone. Counted as ``shed (backlog)``."""
        b = bytes(data[:10])
        if len(b) >= 6 and b[0] == 0xFE:
            msgid = b[5]
        elif len(b) >= 10 and b[0] == 0xFD:
            msgid = b[7] | b[8] << 8 | b[9] << 16
        else:
            msgid = None
        if msgid in self._wanted_ids:
            return False
        self.counts["shed (backlog)"] += 1
        return True

    @property
    def vehicle_time(self) -> float:
        """The latest time on the followed vehicle's clock (−inf before any)."""
        source = self._sources.get(self.system) if self.system is not None else None
        return source.vehicle_time if source is not None else -math.inf

    def _own_time(self, msg: Any) -> float | None:
        value = getattr(msg, self.clock_field, None)
        if value is None or isinstance(value, str | bytes):
            return None
        try:
            t = float(value) * self.clock_scale
        except (TypeError, ValueError):
            return None
        return t if math.isfinite(t) else None

    def _duplicate(self, msg: Any, src: tuple[int, int]) -> bool:
        seq = int(msg.get_seq())
        key = (seq, msg.get_msgId(), msg.get_crc())
        recent = self._recent.setdefault(src, deque(maxlen=_RECENT))
        if key in recent:
            return True
        recent.append(key)
        last = self._seq.get(src)
        if last is not None and 0 < (last - seq) % 256 <= _RECENT:
            self.counts["out of order"] += 1
        else:
            self._seq[src] = seq
        return False


@dataclass
class _Source:
    """What the reader keeps per system: its clock, untimed messages waiting for it, and (before the lock) the
    message types seen and the samples held back."""

    vehicle_time: float = -math.inf
    untimed: list = field(default_factory=list)
    components: dict = field(default_factory=dict)
    seen: set = field(default_factory=set)
    pending: list = field(default_factory=list)
    n_messages: int = 0


# ------------------------------------------------------------------------------------------------- links


def _udp_drops(sock: socket.socket) -> int | None:
    """The kernel's count of datagrams dropped for ``sock`` (receive buffer full): the ``drops`` column of
    ``/proc/net/udp`` (``udp6``), found by the socket's inode; None where there is no such file (not Linux)."""
    try:
        inode = str(os.fstat(sock.fileno()).st_ino)
    except (OSError, ValueError):
        return None
    for table in ("/proc/net/udp", "/proc/net/udp6"):
        try:
            with open(table, encoding="ascii") as fh:
                lines = fh.read().splitlines()[1:]
        except OSError:
            continue
        for line in lines:
            cols = line.split()
            if len(cols) >= 13 and cols[9] == inode:
                return int(cols[-1])
    return None


class Link:
    """An open pymavlink connection read as raw bytes (see :func:`open_link`).

    Attributes
    ----------
    drops_source : str or None
        Where :meth:`kernel_drops` reads the datagrams the kernel dropped (``/proc/net/udp drops column``), None
        when this link or system has no such counter.
    """

    def __init__(self, conn: Any, description: str) -> None:
        from pymavlink import mavutil

        self.conn = conn
        self.description = description
        self.datagram = isinstance(conn, mavutil.mavudp | mavutil.mavmcast)
        port = getattr(conn, "port", None)
        self._socket = port if isinstance(port, socket.socket) and port.type == socket.SOCK_DGRAM else None
        self._drops0 = _udp_drops(self._socket) if self._socket is not None else None
        self.drops_source = "/proc/net/udp drops column" if self._drops0 is not None else None
        self.backlog = False
        self._heartbeat = None
        if isinstance(conn, mavutil.mavtcp) or (isinstance(conn, mavutil.mavudp) and not conn.udp_server):
            self._heartbeat = 0.0  # an outbound link: the other end learns where to send only from us

    def wait(self, timeout: float) -> bool:
        """Wait up to ``timeout`` seconds for data; True when some may be there."""
        self._beat()
        return bool(self.conn.select(timeout))

    def kernel_drops(self) -> int | None:
        """Datagrams the kernel dropped on this link since it was opened (its receive buffer was full); None
        where unknown (see :attr:`drops_source`)."""
        if self._drops0 is None:
            return None
        now = _udp_drops(self._socket)
        return None if now is None else now - self._drops0

    def read(self) -> list[bytes]:
        """What has arrived (up to a bounded batch): datagrams on UDP, chunks otherwise; empty when nothing.

        :attr:`backlog` says whether the batch was full (more is waiting: the reader is behind the link).
        """
        self._beat()
        out = []
        self.backlog = False
        for _ in range(_BATCH):
            try:
                # a byte stream reads what is there (pymavlink would read only the next frame's bytes)
                data = self.conn.recv() if self.datagram else self.conn.recv(_CHUNK)
            except (OSError, ValueError) as exc:
                raise LinkError(f"{self.description}: cannot read ({exc})") from None
            if not data:
                break
            out.append(bytes(data) if not isinstance(data, str) else data.encode("latin-1"))
        else:
            self.backlog = True
        return out

    def _beat(self) -> None:
        if self._heartbeat is None or time.monotonic() - self._heartbeat < 1.0:
            return
        self._heartbeat = time.monotonic()
        try:
            self.conn.mav.heartbeat_send(6, 8, 0, 0, 0)  # a ground station (MAV_TYPE_GCS, no autopilot)
        except (OSError, ValueError):
            pass

    def write(self, data: bytes) -> None:
        self.conn.write(data)

    def close(self) -> None:
        try:
            self.conn.close()
        except (OSError, RuntimeError):
            pass

    def __enter__(self) -> Link:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


def open_link(connection: str, *, receive_buffer: int = _RECEIVE_BUFFER, write: bool = False) -> Link:
    """Open a pymavlink connection string (``udpin:HOST:PORT``, ``udpout:HOST:PORT``, ``tcp:HOST:PORT``, a serial
    device ``/dev/ttyUSB0`` or ``/dev/ttyUSB0:57600``) as a :class:`Link`.

    ``write`` opens it for sending (a replay); a UDP socket's receive buffer is enlarged to ``receive_buffer``
    bytes (up to what the system allows) so a burst does not overflow it while a step is computed.

    Raises
    ------
    LinkError
        The string names no link pymavlink can open, names a file, or the port or device cannot be opened.
    """
    from pymavlink import mavutil

    text = str(connection).strip()
    if not text:
        raise LinkError("empty connection string; e.g. udpin:127.0.0.1:14550, udpout:HOST:PORT, tcp:HOST:PORT")
    if os.path.isfile(text) or text.lower().endswith((".tlog", ".bin", ".log")):
        raise LinkError(f"{text}: a file, not a link; to send a log to a link use: workbench replay {text} --to URL")
    kind, _, rest = text.partition(":")
    port_text = rest.rpartition(":")[2]
    if kind in ("udpin", "udpout", "udp", "udpbcast", "tcp", "tcpin") and port_text.lstrip("+-").isdigit() \
            and not 0 < int(port_text) <= 65535:
        raise LinkError(f"{text}: port {port_text} is not a port number (1–65535)")
    if not write:
        _refuse_shared_port(text)
    device, _, baud = text.rpartition(":") if text.startswith("/dev/") and text.count(":") == 1 else (text, "", "")
    kwargs: dict[str, Any] = {"source_system": 255, "source_component": 0, "robust_parsing": True,
                              "input": not write, "autoreconnect": False}
    if baud:
        if not baud.isdigit():
            raise LinkError(f"{text}: baud rate {baud!r} is not a number")
        kwargs["baud"] = int(baud)
    else:
        device = text
    try:
        conn = mavutil.mavlink_connection(device, **kwargs)
    except (OSError, ValueError, socket.gaierror, OverflowError) as exc:
        raise LinkError(f"{text}: cannot open the link ({exc})") from None
    except Exception as exc:  # pyserial's SerialException and friends
        raise LinkError(f"{text}: cannot open the link ({type(exc).__name__}: {exc})") from None
    if isinstance(conn, mavutil.mavlogfile):
        conn.close()
        raise LinkError(f"{text}: not a link; use udpin:, udpout:, tcp: or a serial device")
    port = getattr(conn, "port", None)
    if isinstance(port, socket.socket) and port.type == socket.SOCK_DGRAM:
        try:
            port.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, receive_buffer)
            # pymavlink binds a listening port with SO_REUSEADDR: clear it, so no later socket can share the port
            # and silently take its traffic
            port.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 0)
        except OSError:
            pass
    return Link(conn, text)


def _refuse_shared_port(text: str) -> None:
    """A listening UDP port already bound by another socket is refused: binding it with SO_REUSEADDR (as
    pymavlink does) would succeed and one of the two listeners would silently get all the traffic."""
    kind, _, rest = text.partition(":")
    if kind not in ("udpin", "udp") or rest.count(":") != 1:
        return
    host, _, port = rest.rpartition(":")
    if not port.isdigit():
        return
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        try:
            probe.bind((host, int(port)))
        except OSError as exc:
            if exc.errno == errno.EADDRINUSE:
                raise LinkError(f"{text}: UDP port {port} is already in use by another program (another "
                                "`workbench live`, MAVProxy, a ground station); stop it or choose another port"
                                ) from None
            # other causes (an address not on this machine …) are pymavlink's to report


# ------------------------------------------------------------------------------------------ tlog → link


def tlog_frames(path: str | os.PathLike) -> Iterator[tuple[float, bytes]]:
    """The records of a tlog as (timestamp in s, raw MAVLink frame), in file order; damaged bytes skipped.

    The frames are the bytes as recorded (sequence numbers, checksums and signatures untouched).
    """
    from pymavlink import mavutil

    from adapters.formats.tlog import looks_like_tlog

    p = Path(path)
    if not p.is_file():
        raise DataError(f"{p}: no such file")
    with open(p, "rb") as fh:
        head = fh.read(64)
    if not looks_like_tlog(head):
        raise FormatError(f"{p}: not a MAVLink telemetry log (.tlog); only a tlog's raw frames can be sent to a link")
    log = mavutil.mavlink_connection(str(p), robust_parsing=True, dialect="ardupilotmega")
    try:
        while True:
            msg = log.recv_msg()
            if msg is None:
                break
            if msg.get_type() == "BAD_DATA":
                continue
            yield float(msg._timestamp), bytes(msg.get_msgbuf())
    finally:
        log.close()


#: The longest a replayed frame waits after the one before it, in seconds of log clock: longer pauses (a damaged
#: stamp, a recording paused for hours) are shortened to this and counted.
MAX_REPLAY_GAP = 10.0


@dataclass(frozen=True)
class SendReport:
    """What :func:`send_tlog` sent: frames, the log's time span and the wall time it took."""

    n_frames: int
    log_seconds: float
    wall_seconds: float
    gaps_capped: int = 0
    seconds_skipped: float = 0.0

    @property
    def speed(self) -> float:
        """Log seconds per wall second actually achieved."""
        return self.log_seconds / self.wall_seconds if self.wall_seconds > 0 else math.inf


def send_tlog(
    path: str | os.PathLike,
    link: Link | str,
    *,
    speed: float = 1.0,
    clock: Callable[[], float] = time.perf_counter,
    sleep: Callable[[float], None] = time.sleep,
    on_frame: Callable[[int, float], None] | None = None,
    should_stop: Callable[[], bool] | None = None,
) -> SendReport:
    """Send a tlog's raw frames to a link, each at its recorded time after the first, divided by ``speed``.

    A frame waits for the time since the frame before it, never more than :data:`MAX_REPLAY_GAP` seconds of log
    clock (and never for a stamp that goes back): one damaged timestamp pushed days ahead costs that long, not
    days. The report counts the gaps so shortened and the log seconds skipped; ``log_seconds`` is the span
    actually replayed.

    Parameters
    ----------
    link : Link or str
        An open link, or a connection string opened here for writing (``udpout:127.0.0.1:14550``).
    on_frame : callable (index, log time), optional
        Called after each frame is sent (progress).
    should_stop : callable, optional
        Polled between frames; True ends the replay early.
    """
    if not (isinstance(speed, int | float) and speed > 0 and math.isfinite(speed)):
        raise DataError(f"replay speed must be a positive number, got {speed!r}")
    own = not isinstance(link, Link)
    out = open_link(link, write=True) if own else link
    n, t_prev, replayed, capped, skipped = 0, math.nan, 0.0, 0, 0.0
    wall0 = clock()
    try:
        for t, frame in tlog_frames(path):
            if n:
                step = max(0.0, t - t_prev)
                if step > MAX_REPLAY_GAP:
                    capped, skipped = capped + 1, skipped + step - MAX_REPLAY_GAP
                    step = MAX_REPLAY_GAP
                replayed += step
            t_prev = t
            delay = wall0 + replayed / speed - clock()
            if delay > 0:
                sleep(delay)
            if should_stop is not None and should_stop():
                break
            try:
                out.write(frame)
            except OSError as exc:
                raise LinkError(f"{out.description}: cannot send ({exc})") from None
            n += 1
            if on_frame is not None:
                on_frame(n, t)
    finally:
        if own:
            out.close()
    return SendReport(n, replayed, clock() - wall0, capped, skipped)

