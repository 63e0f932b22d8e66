"""One meaning per colour across the report's figures.

Hue is taken by two roles only: strategies (blue, orange, …: the demonstrations, the objective's ratios) and
methods (proposed green, IOC-only red, GMR-only purple, persistence brown; the recording near-black). Input
channels (u1, u2, …) are a third role and get no hue of their own — black and gray, told apart by line style and
marker — so blue never means CS1 in one figure and u1 in the next.
"""

from __future__ import annotations

__all__ = ["INPUT_STYLES", "input_style"]

#: (colour, line style, marker) per input channel, in order
INPUT_STYLES = (("#202020", "-", "o"), ("#707070", "-.", "s"), ("#202020", ":", "^"), ("#707070", "--", "D"))


def input_style(k: int) -> dict[str, str]:
    """Matplotlib keyword arguments of the ``k``-th input channel's line."""
    color, ls, marker = INPUT_STYLES[k % len(INPUT_STYLES)]
    return {"color": color, "ls": ls, "marker": marker}
