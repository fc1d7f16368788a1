"""Argument types for angles given in degrees on the command line, and the option group of the
commands that run a chain.

Each type raises :class:`argparse.ArgumentTypeError` with a message that says what was wrong and
what was expected; argparse prefixes it with the option's name (``argument --wi: ...``).
"""

import argparse
import math

THETA_RANGE = "degrees in [0, 90]"
PHI_RANGE = "a finite number of degrees"


def _degrees(text, what, expected):
    text = text.strip()
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{what} {text!r} is not a number; expected {expected}")
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"{what} {text!r} is not finite; expected {expected}")
    return value


def theta(text):
    """A polar angle in degrees, 0 (the normal) to 90 (the horizon)."""
    value = _degrees(text, "theta", THETA_RANGE)
    if not 0.0 <= value <= 90.0:
        raise argparse.ArgumentTypeError(f"theta {value:g} is outside [0, 90] degrees")
    return value


def phi(text):
    """An azimuth in degrees (any finite value; measured from the tangent x towards y)."""
    return _degrees(text, "phi", PHI_RANGE)


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


def seed(text):
    """A non-negative integer seed."""
    try:
        value = int(text)
    except ValueError:
        value = -1
    if value < 0:
        raise argparse.ArgumentTypeError(f"seed {text!r} is not a non-negative integer")
    return value


def starts(text):
    """A number of fit starts: an integer >= 1."""
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected an integer >= 1 (local runs of the fit), "
                                          f"got {text!r}")
    return value


#: brdf.fitting.mcmc.MOVES, named here so that building the parser imports no numpy
MOVES = ("de", "stretch")


def add_chain_options(group):
    """emcee's options, shared by ``fit --mcmc`` and the posterior plots."""
    group.add_argument("--walkers", type=int, metavar="N",
                       help="emcee walkers, even, >= 2 x parameters and >= 4 for de (default: "
                            "max(32, 4 x parameters))")
    group.add_argument("--max-steps", type=int, default=20000, metavar="N",
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
