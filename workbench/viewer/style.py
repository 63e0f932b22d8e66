"""Colors and display names of the viewer: one color per method, per strategy label or flight segment, per mode.

Every colour comes from :mod:`workbench.palette` (one meaning per colour, colour-blind safe), shared with the
report. The viewer's background is dark, so "recorded" is a light gray (the report, on white paper, draws it black).

Bands (Monte Carlo, GMR ±1σ/±3σ, online ±σ) share one neutral tint, :data:`BAND_COLOR`, in every recording and
in the scene: rerun 0.41 draws a time-series band's translucent fill after every line of its plot whatever the
entity order (measured with ``rrd-look``: a green fill turned the IOC-only red (214, 39, 40) into (194, 83, 41)),
so a colored fill would change the hue of every line under it; a neutral one only lightens them. Nested bands (±1σ
inside ±3σ) read by the fill doubling. In the 2-D scene, where draw order is honored, the Monte Carlo envelope is
an opaque dark tint of the same gray under every line (:data:`SCENE_ORDER`).
"""

from __future__ import annotations

import zlib
from collections.abc import Sequence

import numpy as np

from workbench import palette
from workbench.models.registry import REGISTRY

__all__ = [
    "METHOD_COLORS",
    "METHOD_TITLES",
    "RECORDED_COLOR",
    "OUTLIER_COLOR",
    "NO_TRIAL_STATE",
    "NO_TRIAL_COLOR",
    "BAND_COLOR",
    "SCENE_ORDER",
    "color_name",
    "dimmed",
    "min_span",
    "data_range",
    "readable",
    "abbreviate_mode",
    "quiet_corner",
    "label_color",
    "light",
    "method_color",
    "method_title",
    "mode_colors",
    "packed",
    "trial_colors",
    "with_unit",
]

PALETTE: tuple[tuple[int, int, int], ...] = palette.STRATEGY_COLORS  # strategies, segments, overlaid logs
RECORDED_COLOR = palette.RECORDED_SCREEN
# each method's colour and title are its registry entry's (workbench.models.registry), as in the report
METHOD_COLORS: dict[str, tuple[int, int, int]] = {"recorded": RECORDED_COLOR, **{m.name: m.colour for m in REGISTRY}}
METHOD_TITLES = {**{m.name: m.title for m in REGISTRY}, "recorded": "recorded"}
# methods nobody named above get one of the colors no named method uses, the same one on every run
_SPARE = palette.SPARE_METHOD_COLORS
BAND_COLOR = palette.BAND  # every band's fill, see the module docstring
SIGMA1_COLOR = BAND_COLOR
SIGMA3_COLOR = BAND_COLOR
BACKGROUND = (18, 18, 18)  # the viewer's plot background, for dimmed and envelope tints
# draw order in the 2-D scene, bottom to top: the band envelope under the ground, tracks and predictions
SCENE_ORDER = {"band": 1.0, "ground": 1.5, "pad": 2.0, "dimmed": 2.5, "track": 3.0, "starts": 4.0,
               "prediction": 6.0, "scale": 8.0, "vehicle": 10.0, "labels": 20.0}
# the smallest y-span a plot of a quantity in this unit shows: quantization noise (a stick moving by 3 PWM
# counts, a roll of a milliradian) must not fill a plot and read as bang-bang input or oscillation
MIN_SPAN = {"m": 1.0, "m/s": 0.5, "rad": 0.1, "rad/s": 0.2, "deg": 5.0, "deg/s": 10.0, "stick": 0.2, "": 0.0}
COLOR_NAMES = {**{c: n for n, c in palette.OKABE_ITO.items()}, (153, 204, 102): "lime", (255, 170, 187): "pink",
               (166, 118, 29): "brown", (170, 136, 204): "mauve", (238, 221, 136): "light yellow",
               palette.RECORDED_SCREEN: "light gray", palette.BAND: "gray",
               palette.OUTLIER: "magenta", palette.SPARE_METHOD_COLORS[0]: "indigo",
               palette.SPARE_METHOD_COLORS[1]: "purple"}
OUTLIER_COLOR = palette.OUTLIER
# a mode lane's state where no trial is flown (between a flight's segments, after an overlaid trial's end)
NO_TRIAL_STATE = "no trial"
NO_TRIAL_COLOR = palette.LANE_STATES["no trial"]
_MODE_PALETTE = palette.MODE_COLORS


def packed(*colors: Sequence[int]) -> np.ndarray:
    """Colors as packed 0xRRGGBBAA — rerun's fast path; tuples go through a slow per-call conversion."""
    c = np.asarray([tuple(col)[:3] for col in colors], dtype=np.uint32).reshape(-1, 3)
    return (c[:, 0] << 24) | (c[:, 1] << 16) | (c[:, 2] << 8) | np.uint32(255)


def light(color: Sequence[int], amount: float = 0.5) -> tuple[int, int, int]:
    """``color`` mixed with white by ``amount`` (0 keeps it, 1 is white): the tint of a method's band."""
    c = np.asarray(tuple(color)[:3], dtype=float)
    return tuple(int(round(v)) for v in c + amount * (255.0 - c))


def method_color(method: str) -> tuple[int, int, int]:
    """The color of a prediction method, the same in the scene and every plot."""
    if method in METHOD_COLORS:
        return METHOD_COLORS[method]
    return _SPARE[zlib.crc32(method.encode()) % len(_SPARE)]


def method_title(method: str) -> str:
    """A short display name of a method (legends, labels)."""
    return METHOD_TITLES.get(method, method.replace("_", " "))


def label_color(label: str | None, labels: Sequence[str]) -> tuple[int, int, int]:
    """A stable color per strategy label (the order of ``labels``), the recording's for an unlabeled trial."""
    if label is None or label not in labels:
        return RECORDED_COLOR
    return PALETTE[list(labels).index(label) % len(PALETTE)]


def trial_colors(ids: Sequence[str], labels: Sequence[str | None], known: Sequence[str]) -> dict[str, tuple]:
    """One color per strategy label; without labels one color per trial (the segments of a flight)."""
    if any(lab is not None and lab in known for lab in labels):
        return {i: label_color(lab, known) for i, lab in zip(ids, labels, strict=True)}
    return {i: PALETTE[k % len(PALETTE)] for k, i in enumerate(ids)}


def mode_colors(modes: Sequence[str]) -> dict[str, tuple[int, int, int]]:
    """One color per flight mode, in the order the modes are given."""
    return {m: _MODE_PALETTE[k % len(_MODE_PALETTE)] for k, m in enumerate(modes)}


#: A mode span shorter than this share of its lane is labelled by its abbreviation (:func:`abbreviate_mode`):
#: rerun cuts a state's name at its span's end ("STAI" for STABILIZE), which reads as another word
SHORT_SPAN = 0.06


def abbreviate_mode(name: str) -> str:
    """A flight mode's short name, by one rule: names of up to five letters stay; a one-word name keeps its first
    four letters (STABILIZE → STAB, LOITER → LOIT); a name of several words keeps the first word's first three
    letters and each other word's first (ALT_HOLD → ALTH, AUTO_RTL → AUTR); the abbreviation ends with "." so it is
    not read as a word of its own."""
    words = [w for w in name.replace("-", "_").replace(" ", "_").split("_") if w]
    if len(name) <= 5 or not words:
        return name
    short = words[0][:4] if len(words) == 1 else words[0][:3] + "".join(w[0] for w in words[1:])
    return short + "."


def dimmed(color: Sequence[int], amount: float = 0.6) -> tuple[int, int, int]:
    """``color`` mixed with the background by ``amount``: the trials that are not in focus, the scene's envelope."""
    c, b = np.asarray(tuple(color)[:3], dtype=float), np.asarray(BACKGROUND, dtype=float)
    return tuple(int(round(v)) for v in c + amount * (b - c))


def color_name(color: Sequence[int]) -> str:
    """A color's name for a key ("blue"), or its RGB triple."""
    c = tuple(int(v) for v in tuple(color)[:3])
    return COLOR_NAMES.get(c, f"rgb{c}")


def min_span(unit: str) -> float:
    """The smallest y-span of a plot in ``unit`` (:data:`MIN_SPAN`), 0 for an unknown unit."""
    return MIN_SPAN.get(unit, 0.0)


def with_unit(name: str, unit: str) -> str:
    """``"x [m]"``, or just the name without a unit."""
    return f"{name} [{unit}]" if unit else name


def data_range(*arrays: object, margin: float = 0.08, min_span: float = 0.0) -> tuple[float, float]:
    """A y-range holding every finite value of ``arrays``, with ``margin`` of its extent on each side, and at least
    ``min_span`` wide about its middle (:data:`MIN_SPAN`)."""
    lo, hi = np.inf, -np.inf
    for a in arrays:
        a = np.asarray(a, dtype=float).ravel()
        a = a[np.isfinite(a)]
        if a.size:
            lo, hi = min(lo, a.min()), max(hi, a.max())
    if not np.isfinite(lo) or not np.isfinite(hi):
        return -1.0, 1.0
    pad = margin * max(hi - lo, 1e-9, 1e-3 * max(abs(lo), abs(hi)))
    lo, hi = lo - pad, hi + pad
    if hi - lo < min_span:
        mid = (lo + hi) / 2
        lo, hi = mid - min_span / 2, mid + min_span / 2
    return readable(float(lo), float(hi))


#: The most labels rerun's plot puts on an axis: it labels multiples of one power of ten, at least ~25 px apart
#: (measured with rrd-look: 0.1 m steps labelled 31 px apart, not 17 px apart), so a plot ~250 px tall — the
#: workbench's layouts give every plot that much — shows at most about ten
MAX_LABELS = 10
MIN_LABELS = 3


def readable(lo: float, hi: float, min_labels: int = MIN_LABELS) -> tuple[float, float]:
    """``(lo, hi)`` widened, where needed, to hold ``min_labels`` multiples of the power of ten rerun labels.

    rerun's plots (egui_plot) label only multiples of a power of ten, the smallest whose labels do not crowd: a
    y-range of 0.8–2.7 m got the labels 1 and 2, a range of −0.6–0.3 m the label 0 alone (seen with rrd-look). The
    step is estimated for a plot ~250 px tall (:data:`MAX_LABELS`); a taller one labels more, never fewer.
    """
    span = hi - lo
    if not (np.isfinite(span) and span > 0):
        return lo, hi
    step = 10.0 ** np.ceil(np.log10(span / MAX_LABELS))
    k0, k1 = int(np.ceil(lo / step - 1e-9)), int(np.floor(hi / step + 1e-9))
    while k1 - k0 + 1 < min_labels:
        # widen on the side with more room to the next multiple, so the data stay centred
        if (lo - (k0 - 1) * step) <= ((k1 + 1) * step - hi):
            k0 -= 1
        else:
            k1 += 1
    lo, hi = min(lo, k0 * step), max(hi, k1 * step)
    # a label on the very edge of a plot is cut in half: a little room beyond the outer multiples
    edge = 0.04 * (hi - lo)
    return float(lo - edge if np.isclose(lo, k0 * step) else lo), float(hi + edge if np.isclose(hi, k1 * step) else hi)


def quiet_corner(series: Sequence[tuple[np.ndarray, np.ndarray]], t_range: tuple[float, float],
                 y_range: tuple[float, float]) -> str:
    """The corner of a plot (``"LeftTop"``, …) holding the fewest of its points: where a legend hides nothing."""
    (t0, t1), (y0, y1) = t_range, y_range
    counts = dict.fromkeys(("LeftTop", "RightTop", "LeftBottom", "RightBottom"), 0)
    for t, y in series:
        t, y = np.asarray(t, dtype=float), np.asarray(y, dtype=float)
        # a legend covers about a third of the width and height
        left, right = t <= t0 + (t1 - t0) / 3, t >= t1 - (t1 - t0) / 3
        top, bottom = y >= y1 - (y1 - y0) / 3, y <= y0 + (y1 - y0) / 3
        for name, mask in (("LeftTop", left & top), ("RightTop", right & top), ("LeftBottom", left & bottom),
                           ("RightBottom", right & bottom)):
            counts[name] += int(mask.sum())
    return min(counts, key=lambda k: counts[k])  # ties keep the order above: top left first
