"""No command-line error prints Python text (issue 36 §6): the outside attack's cases, each one clear line in the
workbench's words and the status of a bad input (1) or bad arguments (2), never an internal error (3) quoting
``ValueError: Exceeds the limit (4300 digits) for integer string conversion``, ``OverflowError: cannot convert float
infinity to integer``, ``IndexError``, scikit-learn's ``InvalidParameterError`` or pandas' ``C error``.

Each case failed on the previous main (status 3 with a Python exception's text, or library text in the message)."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from workbench.cli import main
from workbench.sim.landing import simulate_landings

from ..forgeries import array_npy, header_json, rewrite_model_file

REPO = Path(__file__).resolve().parents[2]
TLOG = REPO / "sample_logs" / "landing_s00.tlog"
MAPPING = REPO / "adapters" / "mappings" / "planar_quadrotor.toml"
#: What Python (or a library under it) says, never the workbench.
PYTHON_TEXT = re.compile(r"Traceback|\w+Error\b|Exception|Exceeds the limit|integer string conversion|"
                         r"cannot convert float|C error|tokenizing|--debug for the traceback|magic bytes not found")
BIG = "9" * 5000


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("text")
    demos = simulate_landings("CS1", 3, seed=2).save(d / "demos.parquet")
    model = d / "m.npz"
    assert main(["fit", str(demos), "--method", "ioc-only", "--bootstrap", "0", "-q", "-o", str(model)]) == 0
    text = MAPPING.read_text(encoding="utf-8")
    (d / "digits.toml").write_text(text.replace("gap = 0.25", f"gap = {BIG}"), encoding="utf-8")
    (d / "scale.toml").write_text(text.replace("scale = 0.001 }", f"scale = {BIG} }}", 1), encoding="utf-8")
    header = json.loads(__import__("pyarrow.parquet", fromlist=["x"]).read_metadata(demos).metadata[b"workbench"])
    return {"demos": demos, "model": model, "dir": d, "header": header}


def _big_int_in_metadata(files) -> list[str]:
    """A demonstrations file whose stored metadata hold a 5000-digit integer."""
    import pyarrow.parquet as pq

    table = pq.read_table(files["demos"])
    raw = json.dumps(files["header"]).replace('"dt": 0.05', f'"dt": {BIG}')
    bad = files["dir"] / "digits.parquet"
    pq.write_table(table.replace_schema_metadata({b"workbench": raw.encode()}), bad)
    return ["inspect", str(bad)]


def _big_int_in_a_model(files) -> list[str]:
    """A model file whose header holds a 5000-digit integer."""
    bad = rewrite_model_file(files["model"], files["dir"] / "digits.npz",
                             header=lambda text: text.replace('"version": 1', f'"version": {BIG}'))
    return ["predict", "--model", str(bad), "--x0", "0,2,0,0,0,0", "-o", str(files["dir"] / "p.csv")]


def _bounds_of_another_shape(files) -> list[str]:
    """A model file whose plant's input bounds have 100 entries for its 2 inputs (header and arrays agree)."""
    import numpy as np

    def declare(header: dict) -> None:
        header["arrays"]["system/u_min"]["shape"] = [100]

    bad = rewrite_model_file(files["model"], files["dir"] / "bounds.npz", header=header_json(declare),
                             members={"system/u_min": array_npy(np.zeros(100))})
    return ["predict", "--model", str(bad), "--x0", "0,2,0,0,0,0", "-o", str(files["dir"] / "p.csv")]


# name -> (arguments, the status, what the line must say)
CASES = {
    "a 5000-digit integer in a mapping": (
        lambda f: ["import", str(TLOG), "--mapping", str(f["dir"] / "digits.toml"), "-o", str(f["dir"] / "x.parquet")],
        1, r"digits.toml, line \d+: a number too long to read \(more than 4300 digits\)"),
    "a 5000-digit scale in a mapping's channel": (
        lambda f: ["view", str(TLOG), "--mapping", str(f["dir"] / "scale.toml"), "--save", str(f["dir"] / "v.rrd")],
        1, r"scale.toml, line \d+: a number too long to read"),
    "a 5000-digit integer in a file's metadata": (_big_int_in_metadata, 1, r"damaged workbench metadata \(a number "
                                                                        r"too long to read\)"),
    "a 5000-digit integer in a model file's header": (_big_int_in_a_model, 1, "header holds a number too long"),
    "a model's plant whose bounds do not fit it": (_bounds_of_another_shape, 1, r"damaged model file: system: its "
                                                   r"values do not fit together \(system/A \(6, 6\)"),
    "a negative seed": (lambda f: ["fit", str(f["demos"]), "--seed", "-1", "-o", str(f["dir"] / "m2.npz")], 2,
                        r"--seed: expected an integer from 0 to 4294967295, got '-1'"),
    "a seed past 2**32": (lambda f: ["evaluate", str(f["demos"]), "--seed", "99999999999999999999999"], 2,
                          "--seed: expected an integer from 0 to 4294967295"),
    "a 5000-digit seed": (lambda f: ["simulate", "--seed", BIG, "-o", str(f["dir"] / "s.parquet")], 2,
                          r"got '99999999999999999999'… \(5000 characters\)"),
    "negative subjects": (lambda f: ["simulate", "--subjects", "-3", "-o", str(f["dir"] / "s.parquet")], 2,
                          "--subjects: expected an integer of at least 0, got '-3'"),
    "more trials than one call makes": (lambda f: ["simulate", "--trials", "1000", "--subjects", "1000", "-o",
                                                   str(f["dir"] / "s.parquet")], 2, "more than 20000 trials"),
    "an infinite horizon": (lambda f: ["predict", "--model", str(f["model"]), str(f["demos"]), "--horizon", "inf",
                                       "-o", str(f["dir"] / "p.csv")], 2, "--horizon: expected a finite number"),
    "a horizon past any float step count": (lambda f: ["evaluate", str(f["demos"]), "--horizon", "1e308"], 2,
                                            "--horizon: expected at most 600 s"),
    "a stride past any step count": (lambda f: ["evaluate", str(f["demos"]), "--stride", "1e308"], 2,
                                     "--stride: expected at most 600 s"),
    "a horizon that is not a number": (lambda f: ["replay", str(f["demos"]), "--model", str(f["model"]), "--horizon",
                                                  "nan", "--no-wait"], 2, "--horizon: expected a finite number"),
    "more rollouts than a band draws": (lambda f: ["predict", "--model", str(f["model"]), str(f["demos"]),
                                                   "--samples", "100000", "--horizon", "600", "-o",
                                                   str(f["dir"] / "p.csv")], 2, "more than a band draws"),
    "a test size that is no fraction": (lambda f: ["evaluate", str(f["demos"]), "--test-size", "5"], 2,
                                        "--test-size: expected a fraction between 0 and 1"),
    "a log read as CSV": (lambda f: ["inspect", str(TLOG), "--format", "csv"], 1,
                          r"line \d+: \d+ fields, the header has \d+: not a readable CSV \(rows and header differ"),
    "a log read as Parquet": (lambda f: ["fit", str(TLOG), "--format", "parquet", "-o", str(f["dir"] / "m3.npz")], 1,
                              "not a readable Parquet file \\(it does not begin and end with Parquet's magic bytes"),
}


@pytest.mark.parametrize("name", list(CASES))
def test_an_error_is_one_line_in_the_workbenchs_words(files, name, capsys):
    build, status, said = CASES[name]
    try:
        code = main(build(files))
    except SystemExit as exc:  # argparse's own exit for bad arguments
        code = exc.code
    assert code == status
    err = capsys.readouterr().err.strip().splitlines()
    last = err[-1]
    assert re.search(said, last), last
    assert not PYTHON_TEXT.search("\n".join(err)), err
    assert len(last) < 400  # a 5000-digit number is named by its length, not printed


def test_a_protocol_holding_a_5000_digit_integer_is_refused_in_words(tmp_path):
    from workbench.collect.protocol import load_protocol
    from workbench.errors import DataError

    bad = tmp_path / "p.toml"
    bad.write_text(f'title = "t"\nconsent = "c"\ntime_limit_s = {BIG}\n', encoding="utf-8")
    with pytest.raises(DataError, match=r"p.toml: not a protocol \(a number too long to read\)"):
        load_protocol(bad)
