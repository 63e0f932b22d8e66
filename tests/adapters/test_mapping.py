"""Mappings (adapters/mapping.py, adapters/transforms.py): TOML schema, overrides, errors with nearest names."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

import adapters
from adapters.mapping import load_mapping, shipped_mappings
from adapters.selection import channel_inverse, channel_values, select
from adapters.streams import Streams
from adapters.transforms import TRANSFORMS
from workbench.errors import MappingError

BASE = """
dt = 0.1
states = ["a", "b"]
inputs = ["u"]
[channels]
a = "S.x"
b = { source = "S.y", scale = 2.0, offset = 1.0, sign = -1 }
u = "T.stick"
"""


def _mapping(tmp_path, text: str = BASE, name: str = "m.toml"):
    path = tmp_path / name
    path.write_text(text)
    return path


def _streams(**frames) -> Streams:
    return Streams("log.bin", "test", frames, counts={k: len(v) for k, v in frames.items()})


def test_shipped_mappings_load_for_their_formats():
    assert {"planar_quadrotor", "ardupilot_manual", "px4_manual"} <= set(shipped_mappings())
    planar = load_mapping("planar_quadrotor")
    for fmt in ("tlog", "mcap", "csv", "ulog"):
        m = planar.for_format(fmt)
        m.check_complete()
        assert m.state_names == ("x", "y", "phi", "xdot", "ydot", "phidot") and m.input_names == ("u1", "u2")
    ardupilot = load_mapping("ardupilot_manual").for_format("tlog")
    assert ardupilot.segment.mode.keep == (0, 2, 5, 16, 1)  # STABILIZE, ALT_HOLD, LOITER, POSHOLD, ACRO
    assert ardupilot.channel("u1").selector.alternatives == ("RC_CHANNELS_RAW.chan{roll}_raw",)  # by role
    px4 = load_mapping("px4_manual").for_format("ulog")
    assert px4.channel("phi").transform == "quaternion_roll"


def test_a_mapping_without_a_formats_channels_says_which_formats_it_has(tmp_path):
    path = _mapping(tmp_path, 'dt = 1\nstates = ["a"]\ninputs = ["u"]\n[tlog.channels]\na = "X.a"\nu = "X.u"\n')
    m = load_mapping(path)
    m.for_format("tlog").check_complete()
    with pytest.raises(MappingError, match="this mapping has channels for: tlog"):
        m.for_format("mcap").check_complete()


def test_an_unknown_mapping_name_lists_the_shipped_ones():
    with pytest.raises(MappingError) as info:
        load_mapping("ardupilot_manul")
    assert "ardupilot_manual" in str(info.value) and "px4_manual" in str(info.value)


@pytest.mark.parametrize(
    ("text", "needle"),
    [
        ("dt = \n", "not valid TOML"),
        (BASE.replace("dt = 0.1", ""), "dt: missing"),
        (BASE.replace("dt = 0.1", "dt = -1"), "dt: must be positive"),
        (BASE.replace('u = "T.stick"', ""), "no source for ['u']"),
        ('extra = "S.z"\n' + BASE, "unknown key(s) ['extra']"),
        (BASE + 'extra = "S.z"\n', "['extra'] are neither states nor inputs"),
        (BASE.replace("sign = -1", "sign = 3"), "channels.b.sign: must be 1 or -1"),
        (BASE.replace('u = "T.stick"', 'u = { source = "T.stick", transform = "pwn" }'), "unknown transform 'pwn'"),
        (BASE + "[segment]\nmode = { source = \"H.m\", names = \"arducopter\", keep = [\"STABILISE\"] }\n",
         "unknown mode 'STABILISE'"),
        (BASE + "[segment]\nlanding = { state = \"z\" }\n", "'z' is not one of the states"),
        (BASE + "[meta]\nfields = 3\n", "meta.fields"),
        (BASE + '[meta]\nfields = ["id", "lable"]\n', "meta.fields: unknown field 'lable' (did you mean 'label'?)"),
        (BASE + '[meta]\nfields = ["id", "pilot"]\n', "unknown field 'pilot'; known: id, label, subject"),
        ('tlog = 3\n' + BASE, "tlog: must be a table of overrides"),
        (BASE.replace('u = "T.stick"', 'u = { source = "T.stick", transform = ["a"] }'), "unknown transform ['a']"),
        (BASE + "[roles]\nposition = 3\n", "position must be a list of state names"),
        (BASE.replace('inputs = ["u"]', 'inputs = ["a"]'), "are also states"),
        # values checked for meaning (the previous main accepted each of these)
        (BASE.replace('u = "T.stick"', 'u = { source = "T.s", transform = "pwm", pwm_min = 1500, pwm_max = 1500 }'),
         "pwm_min (1500) must be below pwm_max (1500)"),
        (BASE.replace('u = "T.stick"', 'u = { source = "T.s", transform = "pwm", pwm_min = 2000 }'),
         "pwm_min (2000) must be below pwm_max (2000)"),
        (BASE.replace("offset = 1.0", "offset = 1e308"), "channels.b.offset: must be a finite number of magnitude"),
        (BASE.replace("scale = 2.0", "scale = 1e-300"), "channels.b.scale: must not be zero or below"),
        (BASE + "[segment]\nmin_duration = -5\n", "segment.min_duration: must be positive"),
        (BASE + '[segment]\narmed = { source = "H.base_mode", bitmask = 18446744073709551616 }\n',
         "bitmask: must be a positive integer below 2**63"),
    ],
)
def test_invalid_mappings_name_the_file_and_the_key(tmp_path, text, needle):
    path = _mapping(tmp_path, text)
    with pytest.raises(MappingError) as info:
        load_mapping(path)
    assert str(path) in str(info.value)
    assert needle in str(info.value)


def test_values_apply_sign_scale_transform_offset_and_invert(tmp_path):
    m = load_mapping(_mapping(tmp_path))
    s = _streams(S=pd.DataFrame({"t": [0.0, 1.0], "x": [1.0, 2.0], "y": [3.0, 4.0]}))
    ch = m.channel("b")
    values = channel_values(ch, select(ch.selector, s, "b", "m"))
    np.testing.assert_array_equal(values, -2.0 * np.array([3.0, 4.0]) + 1.0)
    np.testing.assert_allclose(channel_inverse(ch, values)[:, 0], [3.0, 4.0])


def test_transforms_invert_and_match_their_definitions():
    rng = np.random.default_rng(0)
    angles = rng.uniform(-1.2, 1.2, 50)
    for name in ("quaternion_roll", "quaternion_pitch", "quaternion_yaw"):
        tr = TRANSFORMS[name]
        q = tr.inverse(angles, {})
        np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0)
        np.testing.assert_allclose(tr.forward(q, {}), angles, atol=1e-12)
    # roll of a rotation about x by r is r (ZYX Euler angles of the quaternion [cos r/2, sin r/2, 0, 0])
    r = 0.3
    assert TRANSFORMS["quaternion_roll"].forward(np.array([[np.cos(r / 2), np.sin(r / 2), 0, 0]]), {})[0] == (
        pytest.approx(r)
    )
    pwm = TRANSFORMS["pwm"]
    np.testing.assert_allclose(pwm.forward(np.array([[1000.0], [1500.0], [2000.0], [2100.0]]), {}), [-1, 0, 1, 1])
    np.testing.assert_allclose(pwm.forward(pwm.inverse(np.array([-0.5, 0.25]), {}), {}), [-0.5, 0.25])
    assert pwm.forward(np.array([[1100.0]]), {"pwm_min": 1100, "pwm_max": 1900})[0] == -1.0


def test_a_missing_stream_lists_the_nearest_names_in_the_file(tmp_path, written):
    path = _mapping(tmp_path, BASE.replace('"S.x"', '"ATTITUDEE.roll"'))
    frames = {"ATTITUDE": pd.DataFrame({"t": [0.0], "roll": [0.0]}), "ATTITUDE_TARGET": pd.DataFrame({"t": [0.0]})}
    s = Streams("flight.tlog", "tlog", frames, counts={"ATTITUDE": 1, "ATTITUDE_TARGET": 1, "HEARTBEAT": 9})
    m = load_mapping(path)
    with pytest.raises(MappingError) as info:
        select(m.channel("a").selector, s, "channel 'a'", m.name)
    message = str(info.value)
    assert "flight.tlog" in message and "'ATTITUDEE.roll'" in message
    assert "nearest: ATTITUDE" in message and "HEARTBEAT" in message


def test_a_missing_field_lists_the_nearest_fields(written):
    with pytest.raises(MappingError) as info:
        adapters.load(written("tlog"), _broken_planar(written, "ATTITUDE.rol"))
    message = str(info.value)
    assert "'rol'" in message and "nearest: roll" in message and str(written("tlog")) in message


def _broken_planar(written, source):
    import tomllib

    from adapters.mapping import MAPPINGS_DIR

    raw = tomllib.loads((MAPPINGS_DIR / "planar_quadrotor.toml").read_text())
    raw["tlog"]["channels"]["phi"] = source
    path = written("tlog").parent / "broken.toml"
    lines = [f"dt = {raw['dt']}", f"states = {raw['states']!r}".replace("'", '"'),
             f"inputs = {raw['inputs']!r}".replace("'", '"'), "[channels]"]
    for name, value in raw["tlog"]["channels"].items():
        if isinstance(value, str):
            lines.append(f'{name} = "{value}"')
        else:
            inner = ", ".join(f'{k} = "{v}"' if isinstance(v, str) else f"{k} = {v}" for k, v in value.items())
            lines.append(f"{name} = {{ {inner} }}")
    path.write_text("\n".join(lines) + "\n")
    return path


def test_alternative_sources_are_tried_in_order(tmp_path):
    text = BASE.replace('u = "T.stick"', 'u = ["RC_CHANNELS.chan1_raw", "RC_CHANNELS_RAW.chan1_raw"]')
    m = load_mapping(_mapping(tmp_path, text))
    s = _streams(RC_CHANNELS_RAW=pd.DataFrame({"t": [0.0], "chan1_raw": [1500]}))
    sel = select(m.channel("u").selector, s, "u", m.name)
    assert sel.stream == "RC_CHANNELS_RAW"
    assert set(m.stream_candidates()) >= {"RC_CHANNELS", "RC_CHANNELS_RAW", "S"}


def test_where_filters_rows_and_the_dominant_system_is_kept(tmp_path):
    hb = pd.DataFrame({
        "t": np.arange(6.0), "custom_mode": [0, 5, 0, 5, 0, 0], "autopilot": [3, 8, 3, 8, 3, 3],
        "sysid": [1, 255, 1, 255, 1, 1], "compid": [1, 0, 1, 0, 1, 1],
    })
    text = BASE.replace('"S.x"', '{ source = "HEARTBEAT.custom_mode", where = { autopilot = 3 } }')
    m = load_mapping(_mapping(tmp_path, text))
    sel = select(m.channel("a").selector, _streams(HEARTBEAT=hb), "a", m.name)
    assert sel.rows.tolist() == [True, False, True, False, True, True]
    plain = load_mapping(_mapping(tmp_path, BASE.replace('"S.x"', '"HEARTBEAT.custom_mode"'), "p.toml"))
    sel = select(plain.channel("a").selector, _streams(HEARTBEAT=hb), "a", plain.name)
    assert sel.rows.sum() == 4 and sel.dropped_other_systems == 2


def test_sources_with_dots_in_stream_names(tmp_path):
    text = BASE.replace('"S.x"', '"/robot/state.pose.x"').replace('"S.y"', '"/robot/state:pose.y"')
    m = load_mapping(_mapping(tmp_path, text))
    frame = pd.DataFrame({"t": [0.0], "pose.x": [1.0], "pose.y": [2.0]})
    s = _streams(**{"/robot/state": frame})
    assert select(m.channel("a").selector, s, "a", m.name).columns == ("pose.x",)
    assert select(m.channel("b").selector, s, "b", m.name).columns == ("pose.y",)


def test_a_source_naming_a_stream_without_a_field_is_a_mapping_error(tmp_path):
    m = load_mapping(_mapping(tmp_path, BASE.replace('"S.x"', '"ATTITUDE."')))
    s = _streams(ATTITUDE=pd.DataFrame({"t": [0.0, 1.0], "roll": [0.0, 0.1]}))
    with pytest.raises(MappingError, match=r"'ATTITUDE\.' names stream 'ATTITUDE' but no field.*roll"):
        select(m.channel("a").selector, s, "channel 'a'", m.name, n_columns=1)


def test_a_clock_field_in_no_channel_stream_is_a_mapping_error(tmp_path, written):
    mapping = _mapping(tmp_path, BASE.replace("dt = 0.1", 'dt = 0.1\nclock = { field = "time_bot_ms", scale = 0.001 }'))
    frames = {"S": pd.DataFrame({"t": np.arange(50) * 0.1, "x": np.zeros(50), "y": np.zeros(50),
                                 "time_boot_ms": np.arange(50) * 100}),
              "T": pd.DataFrame({"t": np.arange(50) * 0.1, "stick": np.zeros(50)})}
    from adapters.pipeline import build

    with pytest.raises(MappingError, match=r"clock field 'time_bot_ms' is in none of the channels' streams"):
        build(_streams(**frames), load_mapping(mapping).for_format("test"))


def test_deeply_nested_toml_is_a_mapping_error(tmp_path):
    path = _mapping(tmp_path, BASE + "deep = " + "[" * 100_000 + "]" * 100_000 + "\n")
    with pytest.raises(MappingError, match="nested deeper"):
        load_mapping(path)  # the previous main let tomllib's RecursionError out


def test_a_mapping_that_is_not_utf8_is_named_by_its_byte(tmp_path):
    """Python's codec text ("'utf-8' codec can't decode byte 0xff") was the message; a library's words."""
    from adapters.mapping import load_mapping
    from workbench.errors import MappingError

    text = b'name = "m"\ndt = 0.1\n# caf\xe9\n'
    path = tmp_path / "latin1.toml"
    path.write_bytes(text)
    with pytest.raises(MappingError) as info:
        load_mapping(path)
    at = text.index(b"\xe9")
    assert str(path) in str(info.value) and f"not UTF-8 text at byte {at}" in str(info.value)
    assert "codec" not in str(info.value)
