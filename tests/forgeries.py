"""How an attacker alters the workbench's own files, and a peer that answers anything: the builders shared by the
tests (``from ..forgeries import …``) and by ``bench/attack`` (which puts the repository on ``sys.path`` and
imports ``tests.forgeries``), so the bench's attacks and the tests that pin their fixes forge the same inputs.
"""

from __future__ import annotations

import io
import json
import socket
import threading
import zipfile
from collections.abc import Callable
from pathlib import Path
from typing import IO, Any

import numpy as np

__all__ = ["altered_copy", "array_npy", "header_json", "inflated", "mcap_messages", "model_header", "npy_header",
           "rewrite_model_file", "serve", "write_mcap", "zeros_npy"]

HEADER_MEMBER = "__header__.npy"  # a model file's header (workbench.models.files: UTF-8 JSON in a uint8 array)


# -- demonstrations -------------------------------------------------------------------------------------------------
def altered_copy(src: Path, dst: Path, how: str) -> Path:
    """The demonstrations file ``src`` rewritten to ``dst`` with every trial shifted by one sample (``"shifted"``),
    1 ulp off (``"ulp"``) or one sample shorter (anything else), under new ids (``<id>-<how>``), keeping its dataset
    metadata: a copy whose bytes and ids repeat nothing of the original's, as if it were another partition."""
    import pyarrow.parquet as pq

    from workbench.data.demonstrations import Demonstration, DemonstrationSet

    ds = DemonstrationSet.load(src)
    out = []
    for d in ds:
        t, x, u = d.t, d.x, d.u
        if how == "shifted":
            t, x, u = t[:-1], x[1:], u[1:]
        elif how == "ulp":
            x, u = np.nextafter(x, np.inf), np.nextafter(u, -np.inf)
        else:
            t, x, u = t[:-1], x[:-1], u[:-1]
        out.append(Demonstration(t, x, u, {**d.meta, "id": f"{d.id}-{how}"}))
    info = json.loads(pq.read_metadata(src).metadata[b"workbench"])["dataset"]
    ds.with_demos(out).save(dst, dataset=info)
    return dst


# -- MCAP -----------------------------------------------------------------------------------------------------------
def mcap_messages(path: Path) -> tuple[Any, list]:
    """An MCAP file's summary and its messages ``(schema, channel, message)`` in file order."""
    from mcap.reader import make_reader

    with path.open("rb") as f:
        reader = make_reader(f)
        return reader.get_summary(), list(reader.iter_messages(log_time_order=False))


def write_mcap(dst: Path, summary: Any, messages: list, moved: int, shift_ns: int) -> Path:
    """``messages`` (as :func:`mcap_messages` reads them) written again by mcap's own writer, with message
    ``moved``'s log_time shifted by ``shift_ns`` (kept at or above 0)."""
    from mcap.writer import Writer

    with dst.open("wb") as f:
        w = Writer(f)
        w.start()
        schemas = {s.id: w.register_schema(s.name, s.encoding, s.data) for s in summary.schemas.values()}
        channels = {c.id: w.register_channel(c.topic, c.message_encoding, schemas.get(c.schema_id, 0), c.metadata)
                    for c in summary.channels.values()}
        for i, (_, ch, m) in enumerate(messages):
            w.add_message(channels[ch.id], max(0, m.log_time + (shift_ns if i == moved else 0)), m.data,
                          m.publish_time, m.sequence)
        w.finish()
    return dst


# -- model files ----------------------------------------------------------------------------------------------------
def npy_header(shape: tuple[int, ...], dtype: str = "<f8") -> bytes:
    """The header of an ``.npy`` member holding an array of ``shape`` and ``dtype`` (its data follow it)."""
    buf = io.BytesIO()
    np.lib.format.write_array_header_1_0(buf, {"descr": dtype, "fortran_order": False, "shape": shape})
    return buf.getvalue()


def zeros_npy(n: int) -> Callable[[IO[bytes]], None]:
    """A member writer: ``n`` float64 zeros, streamed (gigabytes cost no memory; deflated, a few bytes per MB)."""

    def write(f: IO[bytes]) -> None:
        f.write(npy_header((n,)))
        for start in range(0, n * 8, 1 << 24):
            f.write(bytes(min(1 << 24, n * 8 - start)))

    return write


def array_npy(a: np.ndarray) -> Callable[[IO[bytes]], None]:
    """A member writer: the array ``a``."""
    return lambda f: np.save(f, a)


def header_json(change: Callable[[dict], None]) -> Callable[[str], str]:
    """A header rewrite that edits the parsed header in place (``change(header)``)."""

    def rewrite(text: str) -> str:
        header = json.loads(text)
        change(header)
        return json.dumps(header)

    return rewrite


def rewrite_model_file(src: Path, dst: Path, header: Callable[[str], str] | None = None,
                       members: dict[str, Callable[[IO[bytes]], None]] | None = None,
                       compression: int = zipfile.ZIP_STORED) -> Path:
    """The model file ``src`` copied to ``dst`` with its header's JSON text passed through ``header`` and each array
    named in ``members`` written by its writer (:func:`zeros_npy`, :func:`array_npy`): a consistent archive, CRCs
    and sizes as written, whose content says what the forger wants."""
    members = members or {}
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dst, "w", compression) as zout:
        for info in zin.infolist():
            name = info.filename
            if name == HEADER_MEMBER and header is not None:
                text = header(np.load(io.BytesIO(zin.read(info))).tobytes().decode())
                buf = io.BytesIO()
                np.save(buf, np.frombuffer(text.encode(), dtype=np.uint8))
                zout.writestr(name, buf.getvalue())
            elif name.removesuffix(".npy") in members:
                with zout.open(name, "w", force_zip64=True) as f:
                    members[name.removesuffix(".npy")](f)
            else:
                zout.writestr(name, zin.read(info))
    return dst


def model_header(path: Path) -> dict:
    """A model file's header, parsed."""
    with zipfile.ZipFile(path) as zf:
        return json.loads(np.load(io.BytesIO(zf.read(HEADER_MEMBER))).tobytes())


def inflated(src: Path, dst: Path, name: str, n_bytes: int) -> Path:
    """``src`` with its array ``name`` replaced by ``n_bytes`` of zeros, deflated and declared in the header as it is:
    an honest archive whose arrays expand far beyond any model's (2 GB deflate to about 2 MB)."""
    n = n_bytes // 8

    def declare(header: dict) -> None:
        header["arrays"][name]["shape"] = [n]

    return rewrite_model_file(src, dst, header_json(declare), {name: zeros_npy(n)}, zipfile.ZIP_DEFLATED)


# -- peers ----------------------------------------------------------------------------------------------------------
def serve(respond: Callable[[socket.socket], None]) -> tuple[socket.socket, str]:
    """A TCP server on 127.0.0.1 calling ``respond(conn)`` for each connection until it is closed; returns it and
    its address (``tcp://127.0.0.1:<port>``)."""
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen()

    def loop() -> None:
        while True:
            try:
                conn, _ = srv.accept()
            except OSError:
                return
            with conn:
                respond(conn)

    threading.Thread(target=loop, daemon=True).start()
    return srv, f"tcp://127.0.0.1:{srv.getsockname()[1]}"
