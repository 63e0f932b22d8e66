"""Attack round on bounds and losses (issue 29; issue 36: altered dataset copies, model files that expand, hostile
numbers on the command line): hostile sizes, bad stamps, meaningless mapping values, copied and special files in
datasets, replay waits, schedulers, nesting, large standard input.
Not part of the test suite: run it for a bounded time and read the counts.

    PYTHONPATH=. nice .venv/bin/python bench/attack/fuzz_bounds.py --seconds 30   # per surface

Every input is built (and written) before its call, and every file is under 10 MB (:data:`MAX_INPUT`; the
acceptance is about inputs under 10 MB; standard input is streamed by the harness, not built, and may be more).
Each call runs in a child forked from this process (which has imported the workbench and holds no thread), so
the peak memory is the call's own process (``wait4``'s ``ru_maxrss``, with its own children's, the workbench's
imports included) and the time is the call's alone.

Per surface: calls, clean errors (a ``WorkbenchError``, in the workbench's words), foreign errors (anything else,
or a clean error quoting a library: ``ZstdError``, ``codec can't decode``, ``cannot fit``), hangs (a call over
60 s; killed at twice that), silent wrong results (a call that returned but lost or doubled data, accepted a
meaningless value or waited past its bound), the peak resident memory of a call, its longest time and the
largest input file.
"""

from __future__ import annotations

import argparse
import os
import random
import re
import resource
import shutil
import socket
import struct
import subprocess
import sys
import tempfile
import threading
import time
import zlib
from collections.abc import Callable
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO))

from tests import forgeries  # noqa: E402 - the inputs the tests forge too
from workbench.errors import WorkbenchError  # noqa: E402

sys.path.insert(0, str(Path(__file__).parent))
import harness  # noqa: E402 - the shared harness
from harness import HANG_S, _call_in_child, _mutate  # noqa: E402

#: Python's own words in a command's error line (an internal error's class name, a limit, a library's parser).
PYTHON_TEXT = re.compile(r"Traceback|\w+Error:|Exceeds the limit|integer string conversion|cannot convert float|"
                         r"C error|--debug for the traceback|magic bytes not found")
TLOG = REPO / "sample_logs" / "landing_s00.tlog"
MAX_INPUT = 10 << 20  # bytes: every generated input file is smaller


class Tally(harness.Tally):
    """:class:`harness.Tally` with the largest input built per surface (every one under :data:`MAX_INPUT`)."""

    def __init__(self) -> None:
        super().__init__()
        self.largest: dict[str, int] = {}

    def run(self, surface: str, prepare: Callable[[], tuple[Callable[[], str | None], list[Path]]]) -> None:
        call, inputs = prepare()  # built here, outside the call's time and memory
        size = max([q.stat().st_size for q in inputs if q.is_file()], default=0)
        self.largest[surface] = max(self.largest.get(surface, 0), size)
        try:
            if size >= MAX_INPUT:
                raise RuntimeError(f"the harness built a {size >> 20} MiB input")
            outcome = _call_in_child(call)
        finally:
            for q in inputs:
                shutil.rmtree(q, ignore_errors=True) if q.is_dir() else q.unlink(missing_ok=True)
        self.record(surface, outcome, getattr(call, "what", None))

    def columns(self, surface: str) -> dict[str, str]:
        return {**super().columns(surface), "largest input MiB": f"{self.largest[surface] / 2**20:.2f}"}


Prepared = tuple[Callable[[], str | None], list[Path]]


# -- CSV headers -------------------------------------------------------------------------------------------------
def attack_csv_header(rng: random.Random, base: Path) -> Prepared:
    import adapters

    while True:  # a header the size of the acceptance's inputs at most: width x name length under 10 MB
        width = rng.choice([3, 50, 1000, 9_999, 10_001, 100_000, 1_000_000])
        name = rng.choice(["c", "x" * rng.choice([1, 100, 10_000])])
        if width * (len(name) + len(str(width)) + 5) < MAX_INPUT - 1024:
            break
    path = base / f"w{rng.randrange(10**9)}.csv"
    path.write_text("demo,t," + ",".join(f"{name}{i}" for i in range(width)) + "\n" + "a,0," +
                    ",".join("0" for _ in range(width)) + "\na,0.1," + ",".join("1" for _ in range(width)) + "\n")

    def call() -> None:
        adapters.inspect(path)

    return call, [path]


# -- MCAP: honest chunks declaring much, damaged chunks ------------------------------------------------------------
_BOMBS: dict[int, bytes] = {}


def _mcap_bomb(size: int) -> bytes:
    """An MCAP (no summary) with one honest zstd chunk of ``size`` bytes of message records, built streaming."""
    import zstandard

    if size in _BOMBS:
        return _BOMBS[size]
    payload = b'{"a": 1}' + b" " * 60_000
    rec = struct.pack("<BQ", 0x05, 22 + len(payload))
    block, n = b"", 0
    while len(block) < (1 << 20):
        block += rec + struct.pack("<HIQQ", 1, n, n, n) + payload
        n += 1
    cobj = zstandard.ZstdCompressor(level=1).compressobj()
    crc, done, out = 0, 0, []
    while done + len(block) <= size:
        out.append(cobj.compress(block))
        crc = zlib.crc32(block, crc)
        done += len(block)
    out.append(cobj.flush())
    comp = b"".join(out)

    def string(s: bytes) -> bytes:
        return struct.pack("<I", len(s)) + s

    def record(op: int, body: bytes) -> bytes:
        return struct.pack("<BQ", op, len(body)) + body

    schema = record(0x03, struct.pack("<H", 1) + string(b"s") + string(b"jsonschema") + string(b"{}"))
    channel = record(0x04, struct.pack("<HH", 1, 1) + string(b"/x") + string(b"json") + struct.pack("<I", 0))
    chunk = record(0x06, struct.pack("<QQQI", 0, n, done, crc) + string(b"zstd") + struct.pack("<Q", len(comp))
                   + comp)
    header = record(0x01, string(b"") + string(b"bomb"))
    footer = record(0x02, struct.pack("<QQI", 0, 0, 0))
    magic = b"\x89MCAP0\r\n"
    data = magic + header + schema + channel + chunk + footer + magic
    _BOMBS[size] = data
    return data

def attack_mcap_sizes(rng: random.Random, base: Path, sample: bytes) -> Prepared:

    import adapters

    if rng.random() < 0.4:
        data = _mcap_bomb(rng.choice([8 << 20, 64 << 20, 512 << 20, 1 << 30]))
    else:
        data = _mutate(rng, sample)
    path = base / f"m{rng.randrange(10**9)}.mcap"
    path.write_bytes(data)

    def call() -> None:
        adapters.inspect(path)

    return call, [path]


# -- one bad timestamp ---------------------------------------------------------------------------------------------
def _tlog_offsets(data: bytes) -> list[int]:
    offs, off = [], 0
    while off + 10 <= len(data):
        magic, ln = data[off + 8], data[off + 9]
        size = 8 + ln + (12 + (13 if data[off + 10] & 1 else 0) if magic == 0xFD else 8)
        offs.append(off)
        off += size
    return offs


def attack_stamp(rng: random.Random, base: Path, clean: bytes, offsets: list[int], want) -> Prepared:
    data = bytearray(clean)
    off = rng.choice(offsets)
    (stamp,) = struct.unpack(">Q", data[off : off + 8])
    shift = rng.choice([1, -1]) * 2 ** rng.randrange(10, 40)
    data[off : off + 8] = struct.pack(">Q", max(0, stamp + shift))
    path = base / f"s{rng.randrange(10**9)}.tlog"
    path.write_bytes(bytes(data))
    return _loads_whole(path, want, f"stamp +{shift} us at byte {off}"), [path]


def _loads_whole(path: Path, want: tuple[int, int], what: str) -> Callable[[], str | None]:
    """The call: ``path`` loads into ``want`` = (trials, samples). One bad stamp costs at most its sample: the grid
    may lose a step where it sat, never a trial or a run."""

    def call() -> str | None:
        import adapters

        got = adapters.load(path)
        n_demos, n_samples = want
        if len(got) != n_demos or got.n_samples < n_samples - 3:
            return f"{what}: {len(got)} trials / {got.n_samples} samples, not {n_demos} / {n_samples}"
        return None

    return call


def attack_mcap_stamp(rng: random.Random, base: Path, source: tuple[Any, list], want) -> Prepared:
    """One message's log_time moved (the MCAP twin of the tlog stamp): the file rewritten by mcap's own writer."""
    summary, messages = source
    k = rng.randrange(len(messages))
    shift = rng.choice([1, -1]) * 2 ** rng.randrange(20, 50)  # ns: 1 ms to 13 days
    path = forgeries.write_mcap(base / f"t{rng.randrange(10**9)}.mcap", summary, messages, k, shift)
    return _loads_whole(path, want, f"log_time {shift:+d} ns on message {k} ({messages[k][1].topic})"), [path]


# -- mapping values ------------------------------------------------------------------------------------------------
def attack_mapping_values(rng: random.Random, base: Path) -> Prepared:
    import adapters

    text = (REPO / "adapters" / "mappings" / "planar_quadrotor.toml").read_text()
    kind = rng.choice(["offset", "scale", "min_duration", "pwm", "bitmask", "clock", "source", "nested"])
    value = rng.choice(["1e308", "-1e308", "1e13", "1e-300", "0", "-5", "5", "1e12", "2**64", "nan"])
    meaningless = False
    literal = str(2**64) if value == "2**64" else value
    original = text
    if kind == "offset":
        v = float(literal)
        text = re.sub(r"(u2 = \{[^}]*?)scale", rf"\1offset = {literal}, scale", text, count=1)
        meaningless = not abs(v) <= 1e12
    elif kind == "scale":
        v = float(literal)
        text = re.sub(r"scale = 0\.001", f"scale = {literal}", text, count=1)
        meaningless = not 1e-12 <= abs(v) <= 1e12
    elif kind == "min_duration":
        v = float(literal)
        text = re.sub(r"^min_duration = .*$", f"min_duration = {literal}", text, count=1, flags=re.M)
        meaningless = not 0 < v <= 1e12
    elif kind == "pwm":
        lo, hi = rng.choice([(1500, 1500), (2000, 1000), (1000, 2000)])
        text = re.sub(r'(\[tlog\.channels\][^\[]*?u1 = )[^\n]*',
                      rf'\1{{ source = "MANUAL_CONTROL.y", transform = "pwm", pwm_min = {lo}, pwm_max = {hi} }}',
                      text, count=1, flags=re.S)
        meaningless = lo >= hi
    elif kind == "bitmask":
        bit = rng.choice([2**64, 2**63, -1, 0, 128])
        text = text.replace("[tlog.segment]\n", f'[tlog.segment]\narmed = {{ source = "HEARTBEAT.base_mode", '
                            f'bitmask = {bit} }}\n', 1)
        meaningless = not 0 < bit < 2**63
    elif kind == "clock":
        field = rng.choice(["time_boot_ms", "time_bot_ms", "nonexistent"])
        text = text.replace('dt = 0.05', f'dt = 0.05\nclock = {{ field = "{field}", scale = 0.001 }}', 1)
        meaningless = field != "time_boot_ms"
    elif kind == "source":
        text = re.sub(r'(\[tlog\.channels\][^\[]*?x = )"[^"]*"', r'\1"LOCAL_POSITION_NED."', text, count=1,
                      flags=re.S)
        meaningless = True
    else:
        depth = rng.choice([10, 1000, 100_000])
        text += "\nextra = " + "[" * depth + "]" * depth + "\n"
        meaningless = depth >= 50_000  # beyond the parser's recursion; shallower ones are plain TOML
    path = base / f"m{rng.randrange(10**9)}.toml"
    path.write_text(text)

    def call() -> str | None:
        adapters.load(TLOG, mapping=str(path))
        if meaningless and text != original:
            return f"{kind} = {value}: accepted"
        return None

    return call, [path]


# -- datasets: copies, special files -------------------------------------------------------------------------------
def attack_dataset_files(rng: random.Random, base: Path, study) -> Prepared:
    from workbench.data.dataset import load_dataset, write_dataset

    root = base / f"ds{rng.randrange(10**9)}"
    write_dataset(study, root)
    victim = next(root.rglob("*.parquet"))
    action = rng.choice(["copy", "copy_other_subject", "copy_shifted", "copy_ulp", "copy_shorter", "fifo",
                         "self_link", "dangling_link", "device", "socket", "nothing"])
    if action in ("copy_shifted", "copy_ulp", "copy_shorter"):  # a copy altered so neither bytes nor ids repeat
        forgeries.altered_copy(victim, victim.with_name(f"{victim.stem} (copy).parquet"), action.removeprefix("copy_"))
    elif action == "copy":
        shutil.copyfile(victim, victim.with_name(f"{victim.stem} (copy).parquet"))
    elif action == "copy_other_subject":
        other = root / "subject=zz"
        other.mkdir()
        shutil.copyfile(victim, other / victim.name)
    elif action == "fifo":
        os.mkfifo(victim.with_name("x.parquet"))
    elif action == "self_link":
        link = victim.with_name("self.parquet")
        link.symlink_to(link)
    elif action == "dangling_link":
        victim.with_name("gone.parquet").symlink_to(root / "nowhere.parquet")
    elif action == "device":
        victim.with_name("zero.parquet").symlink_to("/dev/zero")
    elif action == "socket":
        s = socket.socket(socket.AF_UNIX)
        s.bind(str(victim.with_name("s.parquet")))
        s.close()

    def call() -> str | None:
        ds = load_dataset(root)
        if len(ds) != len(study):
            return f"{action}: {len(ds)} trials, the dataset holds {len(study)}"
        if action != "nothing":
            return f"{action}: loaded without a word"
        return None

    return call, [*(q for q in root.rglob("*") if q.is_file() and not q.is_symlink()), root]


# -- model files that expand --------------------------------------------------------------------------------------
def attack_model_size(rng: random.Random, base: Path, model: Path, demos: Path) -> Prepared:
    """A model file whose one array is ``size`` bytes of deflated zeros, declared as such (an honest archive: 2 GiB
    deflate to about 2 MB), given to ``predict``."""
    size = rng.choice([8 << 20, 64 << 20, 512 << 20, 2 << 30])
    arrays = forgeries.model_header(model)["arrays"]
    name = rng.choice([k for k in arrays if arrays[k]["shape"]])
    path = forgeries.inflated(model, base / f"m{rng.randrange(10**9)}.npz", name, size)
    out = base / f"p{rng.randrange(10**9)}.csv"

    def call() -> str | None:
        from workbench.cli import main

        return _cli(main, ["predict", "--model", str(path), str(demos), "-o", str(out), "-q"])

    return call, [path, out]


def _cli(main: Callable[[list[str]], int], argv: list[str]) -> str | None:
    """A command run in this (forked) process, judged by its status and its one line: a clean error is raised as
    one (its text checked for Python's), status 3 or Python text is foreign."""
    import contextlib
    import io

    buf = io.StringIO()
    with contextlib.redirect_stderr(buf), contextlib.redirect_stdout(io.StringIO()):
        try:
            code = main(argv)
        except SystemExit as exc:  # argparse's exit for bad arguments
            code = exc.code
    text = buf.getvalue().strip()
    if code == 3 or PYTHON_TEXT.search(text):
        raise RuntimeError(f"exit {code}: {text[-300:]}")
    if code:
        raise WorkbenchError(text.splitlines()[-1] if text else f"exit {code} without a word")
    return None


# -- numbers on the command line ----------------------------------------------------------------------------------
def attack_numbers(rng: random.Random, base: Path, model: Path, demos: Path) -> Prepared:
    """A hostile number in an option or a mapping: huge, negative, 5000 digits, inf, nan, -0, 1e308."""
    words = ["-1", "0", "-0", "1e308", "inf", "-inf", "nan", "9" * 5000, str(2**64), "1e-300", "2.5", "x"]
    value = rng.choice(words)
    out = base / f"o{rng.randrange(10**9)}"
    option = rng.choice(["--seed", "--horizon", "--samples", "--bootstrap", "--power", "--test-size", "--n-test",
                         "--repeats", "--subjects", "--trials", "--workers", "--stride", "--start", "--n-components",
                         "--speed", "--sysid", "--duration", "--silence", "mapping"])
    inputs: list[Path] = []
    if option == "mapping":
        text = (REPO / "adapters" / "mappings" / "planar_quadrotor.toml").read_text(encoding="utf-8")
        key = rng.choice(["gap = 0.25", "min_duration = 0.1", "dt = 0.05"])
        mapping = base / f"m{rng.randrange(10**9)}.toml"
        mapping.write_text(text.replace(key, f"{key.split('=')[0]}= {value}"), encoding="utf-8")
        inputs.append(mapping)
        argv = ["import", str(TLOG), "--mapping", str(mapping), "-o", f"{out}.parquet"]
    elif option in ("--subjects", "--trials"):
        argv = ["simulate", option, value, "--strategy", "CS1", "-o", f"{out}.parquet"]
        if option == "--subjects" and value not in ("-1", "x", "inf", "nan", "-inf", "1e308", "2.5", "-0", "0"):
            argv += ["--trials", "1"]
    elif option == "--duration" and value in ("1e308", str(2**64), "9" * 5000):
        # a finite duration is a request to listen that long (as no --duration is: until Ctrl-C), not a hang
        argv = ["live", "udpin:127.0.0.1:1", "--model", str(model), "--duration", "0.1", "--silence", value,
                "--save", f"{out}.rrd"]
    elif option in ("--speed", "--sysid", "--duration", "--silence"):
        argv = ["live", "udpin:127.0.0.1:1", "--model", str(model), option, value, "--duration", "0.1", "--save",
                f"{out}.rrd"] if option != "--duration" else ["live", "udpin:127.0.0.1:1", "--model", str(model),
                                                             option, value, "--save", f"{out}.rrd"]
        if option == "--speed":
            argv = ["replay", str(demos), "--model", str(model), "--speed", value, "--no-wait", "--save", f"{out}.rrd"]
    elif option in ("--test-size", "--n-test", "--repeats", "--workers", "--stride", "--power"):
        argv = ["evaluate", str(demos), option, value, "--samples", "0", "--no-efficiency", "--n-components", "1",
                "--holdout", "split"]
        if option == "--n-test":
            argv += ["--per-subject"]
    else:
        argv = ["predict", "--model", str(model), str(demos), option, value, "-o", f"{out}.csv"]
    inputs += [Path(f"{out}{s}") for s in (".parquet", ".csv", ".rrd")]

    def call() -> str | None:
        from workbench.cli import main

        return _cli(main, argv)

    call.what = " ".join(a if len(a) < 40 else f"{a[:12]}…({len(a)})" for a in argv)  # named where it hangs
    return call, inputs


# -- replay waits, link ports, speeds ------------------------------------------------------------------------------
def attack_replay(rng: random.Random, base: Path, clean: bytes, offsets: list[int], honest: float) -> Prepared:
    from adapters.link import mavlink
    from workbench.cli import main

    if rng.random() < 0.3:
        port = rng.choice([-1, 0, 65536, 99999, 2**32, 2**64])
        speed = rng.choice(["1e-300", "1e300", "0", "-1", "nan", "inf", "1"])

        def call_args() -> str | None:
            if speed == "1":
                code = main(["replay", str(TLOG), "--to", f"udpout:127.0.0.1:{port}", "--speed", speed, "-q"])
                return f"port {port}: exit {code}" if code != 1 else None
            try:
                main(["replay", str(TLOG), "--to", "udpout:127.0.0.1:14599", "--speed", speed, "-q"])
            except SystemExit as exc:
                if exc.code != 2:
                    return f"--speed {speed}: exit {exc.code}"
                raise WorkbenchError("refused by the parser") from None
            return f"--speed {speed}: accepted"

        return call_args, []
    data = bytearray(clean)
    off = rng.choice(offsets)
    (stamp,) = struct.unpack(">Q", data[off : off + 8])
    data[off : off + 8] = struct.pack(">Q", stamp + 2 ** rng.randrange(20, 44))
    path = base / f"r{rng.randrange(10**9)}.tlog"
    path.write_bytes(bytes(data))

    def call() -> str | None:
        now = [0.0]

        def sleep(s: float) -> None:
            now[0] += s

        mavlink.send_tlog(path, "udpout:127.0.0.1:14599", speed=1.0, clock=lambda: now[0], sleep=sleep)
        if now[0] > honest + 2 * mavlink.MAX_REPLAY_GAP + 1:
            return f"waited {now[0]:.0f} s for a log of {honest:.0f} s"
        return None

    return call, [path]


# -- schedulers ----------------------------------------------------------------------------------------------------
def attack_scheduler(rng: random.Random, empty: str) -> Prepared:
    from workbench.study.executor import DaskExecutor

    address = rng.choice([f"{s}://127.0.0.1:8786" for s in ("tls", "ucx", "ws", "wss", "udp", "http")]
                         + [empty, "tcp://127.0.0.1:99999", "tcp://[::1", "127.0.0.1:1"])

    def call() -> str | None:
        start = time.monotonic()
        ex = DaskExecutor(scheduler=address, timeout=3, worker_wait=2.0)
        ex.close()
        return f"{address}: connected" if time.monotonic() - start < 100 else None

    return call, []


# -- nesting -------------------------------------------------------------------------------------------------------
def attack_nesting(rng: random.Random, base: Path) -> Prepared:
    import numpy as np

    from workbench.models import load_model

    depth = rng.choice([10, 1000, 50_000, 500_000])
    text = ("[" * depth + "]" * depth).encode()
    path = base / f"n{rng.randrange(10**9)}.npz"
    np.savez(path, __header__=np.frombuffer(text, dtype=np.uint8))

    def call() -> str | None:
        load_model(path)
        return "a nested header loaded as a model"

    return call, [path]


# -- large standard input ------------------------------------------------------------------------------------------
def attack_stdin_size(rng: random.Random) -> Prepared:
    """Standard input streamed by the harness (not built: the point is that ``-`` does not hold it); the call
    is ``workbench inspect -``, whose peak memory is the child's children's."""
    size = rng.choice([64 << 20, 256 << 20, 1 << 30])
    head = TLOG.read_bytes()[: 1 << 16]

    def call() -> str | None:
        proc = subprocess.Popen([sys.executable, "-m", "workbench", "inspect", "-", "-q"], stdin=subprocess.PIPE,
                                stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, cwd=REPO,
                                env={**os.environ, "PYTHONPATH": str(REPO)})
        try:
            proc.stdin.write(head)
            block = bytes(1 << 20)
            for _ in range((size - len(head)) >> 20):
                proc.stdin.write(block)
            proc.stdin.close()
        except BrokenPipeError:
            pass
        err = proc.stderr.read().decode(errors="replace")
        code = proc.wait(timeout=HANG_S * 2)
        if code not in (0, 1) or "Traceback" in err:
            raise RuntimeError(f"inspect - ({size >> 20} MiB): exit {code}: {err[-200:]}")
        if code == 1:
            raise WorkbenchError(err.strip())
        return None

    return call, []


def _empty_scheduler() -> tuple[subprocess.Popen, str]:
    """A Dask scheduler with no workers, in its own process (this one must hold no thread: it forks)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    proc = subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1",
                             "--port", str(port), "--dashboard-address", ":0", "--no-show"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    address = f"tcp://127.0.0.1:{port}"
    for _ in range(300):
        with socket.socket() as s:
            if s.connect_ex(("127.0.0.1", port)) == 0:
                return proc, address
        time.sleep(0.1)
    proc.kill()
    raise RuntimeError("the empty Dask scheduler did not start")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=30.0, help="per surface")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--only", action="append")
    args = ap.parse_args()
    rng = random.Random(args.seed)
    sys.path.insert(0, str(Path(__file__).parent))

    import pandas  # noqa: F401 - imported once here, so every forked call starts with it as a command would

    import adapters
    import workbench.cli  # noqa: F401
    from workbench.sim.landing import simulate_study

    clean = TLOG.read_bytes()
    offsets = _tlog_offsets(clean)
    ref = adapters.load(TLOG)
    want = (len(ref), ref.n_samples)
    from adapters.link.mavlink import MAX_REPLAY_GAP, tlog_frames

    times = [t for t, _ in tlog_frames(TLOG)]
    honest = sum(min(max(b - a, 0.0), MAX_REPLAY_GAP) for a, b in zip(times, times[1:], strict=False))
    study = simulate_study(n_subjects=2, n_trials=2, strategy="CS1", seed=1)
    fixtures = Path(tempfile.mkdtemp(prefix="wb-bounds-fixtures-"))
    demos = simulate_study(n_subjects=2, n_trials=4, strategy="CS1", seed=2).save(fixtures / "demos.parquet")
    model = fixtures / "model.npz"
    from workbench.cli import main as cli_main

    if cli_main(["fit", str(demos), "--method", "ioc-only", "--bootstrap", "0", "-q", "-o", str(model)]) != 0:
        raise SystemExit("could not fit the model the model-file surfaces start from")
    sample_mcap = (REPO / "sample_logs" / "landing_s01.mcap").read_bytes()
    mcap_messages = forgeries.mcap_messages(REPO / "sample_logs" / "landing_s01.mcap")
    mcap_ref = adapters.load(REPO / "sample_logs" / "landing_s01.mcap")
    for size in (8 << 20, 64 << 20, 512 << 20, 1 << 30):
        _mcap_bomb(size)  # compressed here, before any call is timed
    base = Path(tempfile.mkdtemp(prefix="wb-bounds-"))
    scheduler, empty = _empty_scheduler()
    if threading.active_count() > 1:
        print(f"warning: {threading.active_count()} threads before forking", file=sys.stderr)
    baseline = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    tally = Tally()
    surfaces = {
        "CSV header width": lambda: attack_csv_header(rng, base),
        "MCAP declared sizes / damage": lambda: attack_mcap_sizes(rng, base, sample_mcap),
        "one bad tlog stamp": lambda: attack_stamp(rng, base, clean, offsets, want),
        "one bad MCAP log_time": lambda: attack_mcap_stamp(rng, base, mcap_messages, (len(mcap_ref),
                                                                                   mcap_ref.n_samples)),
        "mapping values": lambda: attack_mapping_values(rng, base),
        "dataset copies / special files": lambda: attack_dataset_files(rng, base, study),
        "replay waits / ports / speeds": lambda: attack_replay(rng, base, clean, offsets, honest),
        "schedulers (schemes, no workers)": lambda: attack_scheduler(rng, empty),
        "nested model header": lambda: attack_nesting(rng, base),
        "model file sizes (deflated 8 MiB-2 GiB, predict)": lambda: attack_model_size(rng, base, model, demos),
        "numbers (options and a mapping's)": lambda: attack_numbers(rng, base, model, demos),
        "stdin size (streamed, 64 MiB-1 GiB)": lambda: attack_stdin_size(rng),
    }
    if args.only:
        surfaces = {k: v for k, v in surfaces.items() if any(o.lower() in k.lower() for o in args.only)}
    try:
        for name, prepare in surfaces.items():
            end = time.monotonic() + args.seconds
            while time.monotonic() < end:
                tally.run(name, prepare)
            print(f"{name}: {dict(tally.by_surface[name])}, peak {tally.peak[name]:.0f} MiB, slowest call "
                  f"{tally.slowest[name]:.1f} s, largest input {tally.largest[name] / 2**20:.2f} MiB", flush=True)
    finally:
        scheduler.kill()
        scheduler.wait()
        shutil.rmtree(base, ignore_errors=True)
        shutil.rmtree(fixtures, ignore_errors=True)
    print(f"\nEach call forked from a process at {baseline:.0f} MiB (the workbench's imports, the sample logs).")
    tally.print_table(most_examples=8)


if __name__ == "__main__":
    main()

