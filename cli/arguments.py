"""Argument types of the command line, and the option group of the commands that run a chain.

Every option that takes a number has a type from here: :func:`integer` and :func:`number`
take ASCII decimal notation only, refuse NaN and infinities, and check the option's range;
angles are in degrees; :func:`suffixed` checks an output's extension.

Each type raises :class:`argparse.ArgumentTypeError` with a message that says what was wrong and
what was expected; argparse prefixes it with the option's name (``argument --wi: ...``).
"""

import argparse
import math
import re

THETA_RANGE = "degrees in [0, 90]"
PHI_RANGE = "a finite number of degrees"


#: Numbers as the command line takes them: ASCII digits only (Python's int and float also
#: take other scripts' digits, full-width ones and underscores), "inf" and "nan" for the
#: messages that refuse them.
_INTEGER = re.compile(r"[+-]?[0-9]+\Z")
_FLOAT = re.compile(r"[+-]?([0-9]+\.?[0-9]*|\.[0-9]+)([eE][+-]?[0-9]+)?\Z|[+-]?(inf|infinity|nan)\Z",
                    re.IGNORECASE)


def parse_float(text):
    """``float(text)`` for ASCII decimal notation only; ValueError otherwise."""
    text = text.strip()
    if not _FLOAT.match(text):
        raise ValueError(text)
    return float(text)


def parse_int(text):
    """``int(text)`` for ASCII decimal digits only; ValueError otherwise."""
    text = text.strip()
    if not _INTEGER.match(text):
        raise ValueError(text)
    return int(text)


def _range_text(low, high, low_open=False, high_open=False):
    if high is None:
        return f"{'>' if low_open else '>='} {low:g}"
    if low is None:
        return f"{'<' if high_open else '<='} {high:g}"
    return f"in {'(' if low_open else '['}{low:g}, {high:g}{')' if high_open else ']'}"


def integer(low=None, high=None, what="an integer"):
    """An argparse type: a whole number in ``[low, high]`` (either end open when None)."""
    expected = f"{what} {_range_text(low, high)}" if (low, high) != (None, None) else what

    def convert(text):
        try:
            value = parse_int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not a whole number; expected "
                                              f"{expected}") from None
        if (low is not None and value < low) or (high is not None and value > high):
            raise argparse.ArgumentTypeError(f"{value} is out of range; expected {expected}")
        return value
    convert.__name__ = what
    return convert


def number(low=None, high=None, what="a number", low_open=False, high_open=False):
    """An argparse type: a finite number in the range from ``low`` to ``high`` (closed ends
    unless ``low_open``/``high_open``; unbounded when None)."""
    bounded = (low, high) != (None, None)
    expected = (f"{what} {_range_text(low, high, low_open, high_open)}" if bounded
                else f"{what}")

    def convert(text):
        value = _finite(text, "", expected)
        if ((low is not None and (value < low or (low_open and value == low)))
                or (high is not None and (value > high or (high_open and value == high)))):
            raise argparse.ArgumentTypeError(f"{value:g} is out of range; expected {expected}")
        return value
    convert.__name__ = what
    return convert


def suffixed(*suffixes, what="a file"):
    """An argparse type: a path whose name ends in one of ``suffixes`` (case-insensitive)."""
    names = " or ".join(suffixes)

    def convert(text):
        if not text.lower().endswith(suffixes) or len(text) <= len(min(suffixes, key=len)):
            raise argparse.ArgumentTypeError(f"{text!r}: expected {what} named ...{names}")
        return text
    convert.__name__ = what
    return convert


def _finite(text, what, expected):
    """``text`` as a finite float; ArgumentTypeError '<what> <text> is not ...' otherwise."""
    shown = f"{what} {text.strip()!r}" if what else repr(text.strip())
    try:
        value = parse_float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{shown} is not a number; expected {expected}") \
            from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"{shown} is not finite; expected {expected}")
    return value


def theta(text):
    """A polar angle in degrees, 0 (the normal) to 90 (the horizon)."""
    value = _finite(text, "theta", THETA_RANGE)
    if not 0.0 <= value <= 90.0:
        raise argparse.ArgumentTypeError(f"theta {value:g} is outside [0, 90] degrees")
    return value


def phi(text):
    """An azimuth in degrees (any finite value; measured from the tangent x towards y)."""
    return _finite(text, "phi", PHI_RANGE)


def direction(text):
    """``THETA,PHI`` in degrees -> ``(theta, phi)``."""
    parts = text.split(",")
    if len(parts) != 2:
        raise argparse.ArgumentTypeError(f"expected THETA,PHI in degrees (e.g. 30,0), "
                                          f"got {text!r}")
    return theta(parts[0]), phi(parts[1])


def theta_list(text):
    """Comma-separated polar angles in degrees."""
    return [theta(part) for part in text.split(",")]


def phi_list(text):
    """Comma-separated azimuths in degrees."""
    return [phi(part) for part in text.split(",")]


#: A non-negative integer seed.
seed = integer(0, what="a non-negative integer seed")
#: A count of at least one (samples, evaluations, starts, draws).
count = integer(1, what="a whole number")


def theta_below_horizon(text):
    """A polar angle in degrees, 0 up to but not including 90."""
    value = theta(text)
    if value >= 90.0:
        raise argparse.ArgumentTypeError(f"theta {value:g} is not below the horizon; expected "
                                          "degrees in [0, 90)")
    return value


def theta_list_below_horizon(text):
    """Comma-separated polar angles in degrees, each below 90."""
    return [theta_below_horizon(part) for part in text.split(",")]


#: The cutoff of fits and residual plots: a polar angle in (0, 90] degrees.
cutoff = number(0.0, 90.0, "degrees", low_open=True)
#: A 0-based channel index (the library checks it against the subject's channels).
channel = integer(0, what="a channel index")

#: A number of fit starts (local runs): 1 to 100,000.
starts = integer(1, 100_000, "a number of fit starts (local runs)")


#: brdf.fitting.mcmc.MOVES, named here so that building the parser imports no numpy
MOVES = ("de", "stretch")


def add_chain_options(group):
    """emcee's options, shared by ``fit --mcmc`` and the posterior plots."""
    group.add_argument("--walkers", type=integer(2, 100_000, "a walker count"), metavar="N",
                       help="emcee walkers, even, >= 2 x parameters and >= 4 for de (default: "
                            "max(32, 4 x parameters))")
    group.add_argument("--max-steps", type=integer(1, 10_000_000, "a step count"),
                       default=20000, metavar="N",
                       help="cap on the chain length (default: 20000)")
    group.add_argument("--moves", choices=MOVES,
                       help="walker proposals: differential evolution with snooker updates "
                            "(de, default) or emcee's stretch move")


def chain_options(args):
    """brdf.mcmc's keywords from the options of :func:`add_chain_options` (unset ones left to
    its defaults)."""
    options = {"walkers": args.walkers, "max_steps": args.max_steps}
    if args.moves is not None:
        options["moves"] = args.moves
    return options
