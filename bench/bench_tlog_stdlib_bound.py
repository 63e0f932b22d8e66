"""How fast could a tlog's first read be without numpy? A lower bound, for the import-inclusive row of issue 18.

The reader returns numpy columns, and ``import numpy`` alone takes about 0.05 s of the ~0.05 s that 10× pymavlink
leaves on the generated 41-type log. This script times the least a pure-stdlib reader must do, in a fresh process
with its imports on the clock: load the reader's cached dialect specs (JSON; the path is handed in), walk every
frame, check its checksum (``binascii.crc_hqx`` on bit-reversed bytes: MAVLink's X.25 CRC is the reflected CCITT
one), gather each type's zero-padded payloads and unpack them with ``struct.iter_unpack`` into ``array.array``
columns. It skips what a real reader also needs (resynchronisation after damage, unknown ids, text decoding,
column names), so a real one would be slower: if this bound misses the bar, no stdlib reader meets it.

    python bench/bench_tlog_stdlib_bound.py [LOG ...]     (default: a generated 41-type 1 MB log)
"""

from __future__ import annotations

import json
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

_BOUND = r'''
import time, sys
t0 = time.perf_counter()
import binascii, json, struct
from array import array
from pathlib import Path

specs = {s[0]: s for s in json.loads(Path(sys.argv[2]).read_text())}  # the reader's dialect cache, as JSON
REV = bytes(int(f"{i:08b}"[::-1], 2) for i in range(256))
extra = {k: bytes([REV[v[2]]]) for k, v in specs.items()}
b = Path(sys.argv[1]).read_bytes()
rb = b.translate(REV)
n, pos, per, crc_hqx = len(b), 0, {}, binascii.crc_hqx
while pos + 10 <= n:
    plen = b[pos + 9]
    if b[pos + 8] == 0xFD:
        msgid, head, tail = b[pos + 15] | (b[pos + 16] << 8) | (b[pos + 17] << 16), 18, 13 if b[pos + 10] & 1 else 0
    elif b[pos + 8] == 0xFE:
        msgid, head, tail = b[pos + 13], 14, 0
    else:
        break  # damage: a real reader resynchronises here
    pe = pos + head + plen
    if pe + 2 > n or msgid not in specs:
        break
    c = crc_hqx(extra[msgid], crc_hqx(rb[pos + 9 : pe], 0xFFFF))
    if ((REV[c & 0xFF] << 8) | REV[c >> 8]) == (b[pe] | (b[pe + 1] << 8)):
        per.setdefault(msgid, []).append((pos, head, plen))
    pos = pe + 2 + tail
frames = sum(map(len, per.values()))
stamp = struct.Struct(">Q").unpack_from
columns = {}
for msgid, recs in per.items():
    spec = specs[msgid]
    size = spec[6]
    payload = b"".join(b[o + h : o + h + p] + bytes(size - p) for o, h, p in recs)
    cols = list(zip(*struct.Struct(spec[3]).iter_unpack(payload)))
    out = {"t": array("d", [stamp(b, o)[0] * 1e-6 for o, _, _ in recs])}
    for i, col in enumerate(cols):
        out[i] = array("d", col) if isinstance(col[0], float) else array("q", col) if isinstance(col[0], int) else col
    columns[spec[1]] = out
print(json.dumps({"s": time.perf_counter() - t0, "frames": frames, "bytes_walked": pos, "size": n}))
'''

_PEER = r'''
import time, sys, json
t0 = time.perf_counter()
from pymavlink import mavutil
conn = mavutil.mavlink_connection(sys.argv[1])
k = 0
while conn.recv_match(blocking=False) is not None:
    k += 1
print(json.dumps({"s": time.perf_counter() - t0, "messages": k}))
'''

_OURS = r'''
import time, sys, json
t0 = time.perf_counter()
import adapters
adapters.read(sys.argv[1])
print(json.dumps({"s": time.perf_counter() - t0}))
'''


def _run(code: str, *args: object) -> dict:
    out = subprocess.run([sys.executable, "-c", code, *map(str, args)], capture_output=True, text=True, check=True,
                         cwd=ROOT)
    return json.loads(out.stdout.strip().splitlines()[-1])


def measure(path: Path, repeats: int = 5) -> dict:
    sys.path.insert(0, str(ROOT))
    from adapters.formats.mavlink_dialect import _cache_file, load_dialect

    load_dialect()  # writes the dialect cache the reader (and the bound) load from
    cache = _cache_file("ardupilotmega")
    for code, *args in ((_BOUND, path, cache), (_PEER, path), (_OURS, path)):
        _run(code, *args)  # once untimed: bytecode caches as a user's second run has them
    runs = {"bound": [], "peer": [], "ours": [], "frames": 0}
    for _ in range(repeats):
        b = _run(_BOUND, path, cache)
        runs["bound"].append(b["s"])
        runs["frames"] = b["frames"]
        runs["walked"] = b["bytes_walked"] / b["size"]
        runs["peer"].append(_run(_PEER, path)["s"])
        runs["ours"].append(_run(_OURS, path)["s"])
    return {k: statistics.median(v) if isinstance(v, list) else v for k, v in runs.items()}


def main() -> None:
    paths = [Path(p) for p in sys.argv[1:]]
    with tempfile.TemporaryDirectory() as tmp:
        if not paths:
            sys.path.insert(0, str(Path(__file__).parent))
            from bench_readers import generate_many_types

            paths = [Path(tmp) / "many_types_1MB.tlog"]
            generate_many_types(paths[0])
        print("| log | frames | pymavlink import + read | 10× leaves | stdlib bound | ours (numpy) | bound's ratio |")
        print("|---|---|---|---|---|---|---|")
        for path in paths:
            m = measure(path)
            partial = "" if m["walked"] > 0.999 else f" (stopped at damage, {m['walked']:.0%} walked)"
            print(f"| {path.name} | {m['frames']}{partial} | {m['peer']:.3f} s | {m['peer'] / 10:.3f} s | "
                  f"{m['bound']:.3f} s | {m['ours']:.3f} s | {m['peer'] / m['bound']:.1f}× |")


if __name__ == "__main__":
    main()
