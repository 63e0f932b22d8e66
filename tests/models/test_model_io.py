"""Model files that are damaged inside their zip archive: clear ModelFileErrors, no allocation of declared sizes.

(Round trips and header-level damage of whole models are in test_model.py; these tests build files with
:func:`write_model_file` directly, then damage one ``.npy`` member the way a bad disk or a cut download does.)
"""

from __future__ import annotations

import tracemalloc
import zipfile
from pathlib import Path

import numpy as np
import pytest

from workbench.cli import main
from workbench.errors import ModelError
from workbench.models.files import ModelFileError, read_model_file, write_model_file

from ..forgeries import inflated, npy_header

ARRAYS = {"K": np.arange(12.0).reshape(2, 6), "counts": np.arange(5), "scale": np.linspace(0.0, 1.0, 400)}


@pytest.fixture
def good(tmp_path) -> Path:
    return write_model_file(tmp_path / "good.npz", "HumanBehaviorModel", {"settings": {}}, ARRAYS)


def _replace_member(src: Path, dst: Path, name: str, payload: bytes, compress: int = zipfile.ZIP_DEFLATED) -> Path:
    """A copy of ``src`` with member ``name`` replaced by ``payload`` (a consistent archive: CRCs match)."""
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dst, "w", compression=compress) as zout:
        for info in zin.infolist():
            zout.writestr(info.filename, payload if info.filename == name else zin.read(info))
    return dst


def _garble_deflate_stream(src: Path, dst: Path, name: str) -> Path:
    """``src`` with the compressed bytes of member ``name`` overwritten in place (the zip structure intact)."""
    data = bytearray(src.read_bytes())
    with zipfile.ZipFile(src) as zf:
        info = zf.getinfo(name)
    # local file header: 30 fixed bytes, then the name and the extra field, whose lengths sit at offsets 26, 28
    start = info.header_offset + 30 + int.from_bytes(data[info.header_offset + 26:info.header_offset + 28], "little")
    start += int.from_bytes(data[info.header_offset + 28:info.header_offset + 30], "little")
    # 0xFF opens a final deflate block of the reserved type 3: zlib must reject it
    data[start:start + info.compress_size] = b"\xff" * info.compress_size
    dst.write_bytes(bytes(data))
    return dst


def test_good_file_reads_back_exactly(good):
    mf = read_model_file(good)
    assert set(mf.arrays) == set(ARRAYS)
    for k, v in ARRAYS.items():
        assert mf.arrays[k].dtype == (np.float64 if v.dtype.kind == "f" else np.int64)
        np.testing.assert_array_equal(mf.arrays[k], v)
        assert mf.arrays[k].flags.writeable


def test_huge_declared_shape_is_refused_before_allocating(good, tmp_path):
    """A header declaring 10⁶ × 10⁶ float64 (8 TB) over 96 bytes of data: an error, not an 8 TB allocation."""
    payload = npy_header((10**6, 10**6)) + ARRAYS["K"].tobytes()
    for compress in (zipfile.ZIP_DEFLATED, zipfile.ZIP_STORED):
        bad = _replace_member(good, tmp_path / f"huge{compress}.npz", "K.npy", payload, compress)
        tracemalloc.start()
        with pytest.raises(ModelFileError, match=r"declares shape \(1000000, 1000000\)") as info:
            read_model_file(bad)
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        assert str(bad) in str(info.value) and "'K.npy'" in str(info.value)
        assert peak < 100 * bad.stat().st_size  # nothing near the declared size was allocated


def test_member_claiming_more_than_its_compressed_bytes_can_hold_is_refused(good, tmp_path):
    data = bytearray(good.read_bytes())
    entry = data.find(b"PK\x01\x02")  # central directory entries: the name's length at 28, the name at 46
    while entry != -1:
        name_len = int.from_bytes(data[entry + 28:entry + 30], "little")
        if bytes(data[entry + 46:entry + 46 + name_len]) == b"scale.npy":
            break
        entry = data.find(b"PK\x01\x02", entry + 4)
    assert entry != -1
    data[entry + 24:entry + 28] = (2**32 - 2).to_bytes(4, "little")  # its uncompressed size: almost 4 GB
    bad = tmp_path / "claims.npz"
    bad.write_bytes(bytes(data))
    with pytest.raises(ModelFileError, match=r"claim.* bytes.*, more than .* can hold") as exc:
        read_model_file(bad)
    assert str(bad) in str(exc.value)


def test_corrupt_deflate_stream_is_a_model_file_error(good, tmp_path):
    bad = _garble_deflate_stream(good, tmp_path / "zlib.npz", "scale.npy")
    with pytest.raises(ModelFileError, match="damaged model file") as info:
        read_model_file(bad)
    assert str(bad) in str(info.value)
    assert isinstance(info.value, ModelError)


def _stored_with_flipped_bit(good: Path, dst: Path, array: np.ndarray, offset: int) -> Path:
    """An uncompressed copy of ``good`` with one bit of ``array``'s data flipped: only the CRC-32 can tell."""
    _replace_member(good, dst, "no such member", b"", zipfile.ZIP_STORED)
    raw = bytearray(dst.read_bytes())
    at = raw.find(array.tobytes())
    assert at > 0
    raw[at + offset] ^= 0x10
    dst.write_bytes(bytes(raw))
    return dst


def test_bad_crc_and_object_dtype_are_model_file_errors(good, tmp_path):
    crc = _stored_with_flipped_bit(good, tmp_path / "crc.npz", ARRAYS["counts"], 0)
    with pytest.raises(ModelFileError, match="CRC") as exc:
        read_model_file(crc)
    assert str(crc) in str(exc.value)
    obj = _replace_member(good, tmp_path / "obj.npz", "counts.npy", npy_header((1,), "|O") + b"\0" * 8)
    with pytest.raises(ModelFileError, match="non-numeric dtype"):
        read_model_file(obj)


@pytest.mark.parametrize("damage", ["zlib", "huge shape", "truncated", "text", "crc"])
def test_cli_prints_one_line_naming_the_file(good, tmp_path, capsys, damage):
    if damage == "zlib":
        bad = _garble_deflate_stream(good, tmp_path / "bad.npz", "__header__.npy")
    elif damage == "huge shape":
        bad = _replace_member(good, tmp_path / "bad.npz", "scale.npy", npy_header((2**40,)) + b"\0" * 64)
    elif damage == "truncated":
        bad = tmp_path / "bad.npz"
        bad.write_bytes(good.read_bytes()[:-40])
    elif damage == "text":
        bad = tmp_path / "bad.npz"
        bad.write_text("not a model")
    else:
        bad = _stored_with_flipped_bit(good, tmp_path / "bad.npz", ARRAYS["scale"], 9)
    code = main(["predict", "--model", str(bad), "--x0", "0,0,0,0,0,0", "-o", str(tmp_path / "p.csv")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 1
    assert len(err) == 1 and err[0].startswith("error: ") and str(bad) in err[0], err
    assert "error: error" not in err[0]


@pytest.fixture(scope="module")
def ioc_model(tmp_path_factory) -> Path:
    from workbench.models import IOCOnlyModel
    from workbench.plant.system import planar_quadrotor
    from workbench.sim.landing import simulate_landings

    ds = simulate_landings("CS1", 3, seed=5)
    return IOCOnlyModel(planar_quadrotor(dt=ds.dt)).fit(ds).save(tmp_path_factory.mktemp("ioc") / "m.npz")


@pytest.mark.parametrize(
    ("where", "value"),
    [(("settings",), [1, 2]), (("settings",), 3), (("fit",), 2.5), (("arrays", "K", "shape"), None),
     (("arrays", "K"), "x"), (("system",), "x"), (("system", "dt"), "fast")],
)
def test_header_entries_of_the_wrong_kind_are_model_file_errors(ioc_model, tmp_path, where, value):
    """A header rewritten by hand (the zip's CRCs intact) whose entries hold the wrong kinds of values."""
    import json

    from workbench.models import load_model

    with np.load(ioc_model) as npz:
        arrays = {k: npz[k] for k in npz.files}
    header = json.loads(arrays["__header__"].tobytes())
    node = header
    for key in where[:-1]:
        node = node[key]
    node[where[-1]] = value
    arrays["__header__"] = np.frombuffer(json.dumps(header).encode(), dtype=np.uint8)
    bad = tmp_path / "bad.npz"
    with open(bad, "wb") as fh:
        np.savez(fh, **arrays)
    with pytest.raises(ModelFileError) as info:
        load_model(bad)
    assert str(bad) in str(info.value)


def test_a_model_file_expanding_past_the_ceiling_is_refused_before_it_is_read(good, tmp_path, monkeypatch):
    """Issue 36: a 2.0 MB model file (one deflated 2 GB array) took `predict` to 4.1 GB; now the archive's declared
    size is held against MAX_DECOMPRESSED_BYTES before any member is decompressed (here lowered to 1 MiB, with an
    8 MiB array, so the test is fast; the full-size file is the slow test below)."""
    from workbench.models import files

    monkeypatch.setattr(files, "MAX_DECOMPRESSED_BYTES", 1 << 20)
    bomb = inflated(good, tmp_path / "bomb.npz", "scale", 8 << 20)
    assert bomb.stat().st_size < 64 << 10
    tracemalloc.start()
    with pytest.raises(ModelFileError, match=r"not read: its arrays expand to \d+ bytes, more than a model file holds "
                                             r"\(at most 1048576 bytes: workbench.models.files.MAX_DECOMPRESSED_BYTES"):
        read_model_file(bomb)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert peak < 1 << 20  # the previous main decompressed the 8 MiB (and copied it) before refusing its shape


@pytest.mark.slow
def test_predict_on_a_two_megabyte_model_bomb_stays_under_a_gigabyte(good, tmp_path):
    """The attack's file itself: 2 GB of zeros deflated into about 2 MB, given to `predict` in a process of its own
    whose peak resident memory is measured (the previous main: 4.1 GB, or a MemoryError under a 4 GB cap)."""
    import resource
    import subprocess
    import sys

    from workbench.sim.landing import simulate_landings

    bomb = inflated(good, tmp_path / "bomb.npz", "scale", 2_000_000_000)
    assert bomb.stat().st_size < 10 << 20
    demos = simulate_landings("CS1", 2, seed=0).save(tmp_path / "d.parquet")
    run = subprocess.run([sys.executable, "-m", "workbench", "predict", "--model", str(bomb), str(demos), "-o",
                          str(tmp_path / "p.csv")], capture_output=True, text=True, timeout=300)
    peak_mb = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
    assert run.returncode == 1 and "more than a model file holds" in run.stderr
    assert peak_mb < 1024, peak_mb
