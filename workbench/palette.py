"""One palette for every picture the workbench draws (report figures and rerun recordings): one meaning per colour.

Each role has its own colours and no colour serves two roles (``tests/test_palette.py`` checks it):

* **methods** — the Okabe–Ito colours (Okabe & Ito 2008, "Color Universal Design"), chosen so the four methods
  and the recording stay apart under a deuteranopia and a protanopia simulation (Machado, Oliveira & Fernandes
  2009); each method also has a line style and a marker (:mod:`workbench.models.registry` assigns them), so they
  differ by more than hue;
* **the recording** — black on paper, light gray on the viewer's dark background;
* **strategies, flight segments and overlaid logs** — the other Okabe–Ito hues, then a few of Paul Tol's, far
  from every method colour; ŵ takes its trial's strategy colour;
* **bands** (Monte Carlo, GMR ±1σ/±3σ, online) — one neutral gray everywhere, so a band's fill changes no line's hue;
* **outliers** (ŵ outside its 3σ band) — a magenta no other role uses;
* **flight modes** — a third set (Paul Tol's muted scheme), **stick channels and setpoints** a fourth, lanes of
  what a mapping kept (and armed spans) in grays with their names written on them;
* **a trial's outcome** in the testbed's experimenter's view (landed, crashed, left the domain, time limit) — a
  fifth set, far from every method colour and apart from each other under the colour-blindness simulations.

This module is data only (floor 0): the report turns the triples into hex strings, the viewer packs them.
"""

from __future__ import annotations

__all__ = [
    "RGB", "OKABE_ITO", "METHOD_COLORS", "SPARE_METHOD_COLORS", "RECORDED_PAPER", "RECORDED_SCREEN",
    "STRATEGY_COLORS", "BAND", "OUTLIER", "MODE_COLORS", "STICK_COLORS", "SETPOINT", "LANE_STATES", "OUTCOME_COLORS",
    "ROLES",
    "hex_color", "strategy_color", "CVD_MATRICES", "simulate", "lab", "delta_e",
]

RGB = tuple[int, int, int]

#: Okabe & Ito (2008), the colour-blind-safe qualitative palette
OKABE_ITO: dict[str, RGB] = {
    "black": (0, 0, 0), "orange": (230, 159, 0), "sky blue": (86, 180, 233), "bluish green": (0, 158, 115),
    "yellow": (240, 228, 66), "blue": (0, 114, 178), "vermillion": (213, 94, 0), "reddish purple": (204, 121, 167),
}
#: the methods' colours, in the registry's order (proposed, IOC-only, GMR-only, persistence)
METHOD_COLORS: tuple[RGB, ...] = (OKABE_ITO["blue"], OKABE_ITO["vermillion"], OKABE_ITO["sky blue"],
                                  OKABE_ITO["bluish green"])
#: a method no declaration names gets one of these, the same one on every run; the first (an indigo) also stays apart
#: from the four and the recorded trace under deuteranopia and protanopia, so a fifth declared method can take it
#: (its declaration's colour 4: tests/test_extensions.py adds one)
SPARE_METHOD_COLORS: tuple[RGB, ...] = ((51, 51, 204), (170, 68, 153))
RECORDED_PAPER: RGB = (0, 0, 0)
RECORDED_SCREEN: RGB = (225, 225, 225)
#: strategies (CS1, CS2, …), the segments of a flight and the logs of an overlay, in order
STRATEGY_COLORS: tuple[RGB, ...] = (OKABE_ITO["orange"], OKABE_ITO["reddish purple"], OKABE_ITO["yellow"],
                                    (153, 204, 102), (255, 170, 187), (166, 118, 29), (170, 136, 204),
                                    (238, 221, 136))
#: every band's fill, in the report (with transparency) and in the viewer
BAND: RGB = (187, 187, 187)
OUTLIER: RGB = (238, 51, 119)
#: flight modes (Paul Tol's muted scheme), in the order a log's modes first appear
MODE_COLORS: tuple[RGB, ...] = ((68, 170, 153), (221, 204, 119), (204, 102, 119), (51, 34, 136), (153, 153, 51),
                                (136, 34, 85), (17, 119, 51), (221, 170, 119))
#: the raw log's stick channels (roll, pitch, throttle, yaw) and an attitude's setpoint
STICK_COLORS: dict[str, RGB] = {"roll": (204, 170, 255), "pitch": (153, 238, 204), "throttle": (255, 204, 153),
                                "yaw": (187, 204, 51)}
SETPOINT: RGB = (238, 136, 102)
#: lanes whose states are written on them: what a mapping kept or dropped, armed spans, no trial flown
LANE_STATES: dict[str, RGB] = {
    "kept": (210, 210, 210), "disarmed": (120, 120, 120), "too short": (95, 95, 95), "gap": (80, 80, 80),
    "missing channel": (105, 105, 105), "not mapped": (60, 60, 60), "armed": (200, 200, 200),
    "no trial": (55, 55, 55), "on the ground": (140, 100, 60),  # earth brown: armed, landed, cut by the import
}  # fmt: skip

#: a collected trial's outcome (the testbed's experimenter's view): a green, a red, an ochre, a purple
OUTCOME_COLORS: dict[str, RGB] = {"landed": (102, 170, 85), "crashed": (220, 50, 32),
                                  "left the domain": (204, 187, 68), "time limit": (170, 51, 119)}

#: every role and its colours, for the test that no two roles share one
ROLES: dict[str, tuple[RGB, ...]] = {
    "method": METHOD_COLORS + SPARE_METHOD_COLORS, "recorded": (RECORDED_PAPER, RECORDED_SCREEN),
    "strategy": STRATEGY_COLORS, "band": (BAND,), "outlier": (OUTLIER,), "mode": MODE_COLORS,
    "stick": tuple(STICK_COLORS.values()) + (SETPOINT,), "lane": tuple(dict.fromkeys(LANE_STATES.values())),
    "outcome": tuple(OUTCOME_COLORS.values()),
}


def hex_color(rgb: RGB) -> str:
    """``"#0072b2"`` for matplotlib."""
    return "#" + "".join(f"{int(c):02x}" for c in rgb[:3])


def strategy_color(k: int) -> RGB:
    """The ``k``-th strategy's (segment's, overlaid log's) colour, cycling past the set's end."""
    return STRATEGY_COLORS[k % len(STRATEGY_COLORS)]


# -- colour-vision simulation, to check the palette (tests/test_palette.py) ------------------------------------------
#: Machado, Oliveira & Fernandes (2009), "A physiologically-based model for simulation of color vision deficiency",
#: IEEE TVCG 15(6): the severity-1.0 matrices, applied to linear RGB
CVD_MATRICES: dict[str, tuple[tuple[float, float, float], ...]] = {
    "deuteranopia": ((0.367322, 0.860646, -0.227968), (0.280085, 0.672501, 0.047413),
                     (-0.011820, 0.042940, 0.968881)),
    "protanopia": ((0.152286, 1.052583, -0.204868), (0.114503, 0.786281, 0.099216),
                   (-0.003882, -0.048116, 1.051998)),
}


def _to_linear(c: float) -> float:
    c /= 255.0
    return c / 12.92 if c <= 0.04045 else ((c + 0.055) / 1.055) ** 2.4


def _to_srgb(v: float) -> float:
    v = min(max(v, 0.0), 1.0)
    return 255.0 * (12.92 * v if v <= 0.0031308 else 1.055 * v ** (1 / 2.4) - 0.055)


def simulate(rgb: RGB, deficiency: str) -> tuple[float, float, float]:
    """``rgb`` as a viewer with ``deficiency`` (a key of :data:`CVD_MATRICES`) sees it, in sRGB 0–255."""
    lin = [_to_linear(c) for c in rgb[:3]]
    return tuple(_to_srgb(sum(m * v for m, v in zip(row, lin, strict=True))) for row in CVD_MATRICES[deficiency])


def lab(rgb: tuple[float, float, float]) -> tuple[float, float, float]:
    """CIE L*a*b* (D65) of an sRGB colour."""
    r, g, b = (_to_linear(c) for c in rgb[:3])
    xyz = (0.4124 * r + 0.3576 * g + 0.1805 * b) / 0.95047, 0.2126 * r + 0.7152 * g + 0.0722 * b, \
        (0.0193 * r + 0.1192 * g + 0.9505 * b) / 1.08883
    f = [v ** (1 / 3) if v > 0.008856 else 7.787 * v + 16 / 116 for v in xyz]
    return 116 * f[1] - 16, 500 * (f[0] - f[1]), 200 * (f[1] - f[2])


def delta_e(a: tuple[float, float, float], b: tuple[float, float, float]) -> float:
    """CIE76 colour difference of two sRGB colours (about 2.3 is just noticeable; 10 and more reads as another
    colour at a glance)."""
    return sum((p - q) ** 2 for p, q in zip(lab(a), lab(b), strict=True)) ** 0.5
