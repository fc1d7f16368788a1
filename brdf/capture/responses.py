"""Camera responses: the inverse transfer functions that turn a photograph's codes into linear
values, and their slopes (how far apart in linear units two neighbouring codes lie, which sets
the quantisation noise).

- ``linear``: the code is the value (EXR files, raw developers' linear TIFFs);
- ``srgb``: the sRGB electro-optical transfer function (IEC 61966-2-1:1999, section 4.2, the
  piecewise curve with a linear toe below 0.04045);
- ``gamma:G``: a pure power law, value = code^G (G in (0, 10]).
"""

from dataclasses import dataclass

import numpy as np

from ..arguments import shown
from ..errors import InputError

__all__ = ["Response", "response", "RESPONSES"]

#: The responses by name, for help texts.
RESPONSES = ("linear", "srgb", "gamma:G")


@dataclass(frozen=True)
class Response:
    """An inverse camera response: codes in [0, 1] -> linear values (:meth:`decode`)."""

    name: str
    gamma: float = 1.0

    def decode(self, c):
        """Linear values of codes ``c`` in [0, 1]."""
        c = np.asarray(c, dtype=float)
        if self.name == "srgb":
            # IEC 61966-2-1:1999, 4.2: linear toe below 0.04045, a 2.4 power law above
            return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)
        if self.name == "gamma":
            return c ** self.gamma
        return c

    def slope(self, c):
        """d(value)/d(code) at codes ``c``: the linear width of one quantisation step, divided
        by the step in codes."""
        c = np.asarray(c, dtype=float)
        if self.name == "srgb":
            # derivative of decode (IEC 61966-2-1:1999, 4.2)
            return np.where(c <= 0.04045, 1.0 / 12.92,
                            2.4 / 1.055 * ((c + 0.055) / 1.055) ** 1.4)
        if self.name == "gamma":
            return self.gamma * np.maximum(c, 0.0) ** (self.gamma - 1.0)
        return np.ones_like(c)

    def __str__(self):
        return f"gamma:{self.gamma:g}" if self.name == "gamma" else self.name


def response(text):
    """A :class:`Response` from ``linear``, ``srgb`` or ``gamma:G``."""
    if isinstance(text, Response):
        return text
    if not isinstance(text, str):
        raise InputError(f"response: expected linear, srgb or gamma:G, got {shown(text)}")
    name, _, value = text.strip().lower().partition(":")
    if name in ("linear", "srgb") and not value:
        return Response(name)
    if name == "gamma":
        try:
            g = float(value)
        except ValueError:
            g = float("nan")
        if not 0.0 < g <= 10.0:
            raise InputError(f"response {text!r}: expected gamma:G with G in (0, 10], e.g. "
                             "gamma:2.2")
        return Response("gamma", g)
    raise InputError(f"response: expected linear, srgb or gamma:G, got {text!r}")
