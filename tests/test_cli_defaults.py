"""The command line's defaults are the library's: every option of a subcommand named like a
parameter of the library function it calls has that parameter's default, so a user who moves
from ``brdf-fit`` to Python (or back) gets the same fit, render or lobe."""

import argparse
import importlib
import inspect

import pytest

import brdf.capture
import brdf.demo
import brdf.gonioreflectometer
import brdf.precompile
import brdf.properties
import brdf.render
import brdf.viz.lobes
from brdf_cli.main import build_parser

# brdf.fitting exports functions under the names of these modules
batch, compare, mcmc, nlopt_fit = (importlib.import_module(f"brdf.fitting.{name}")
                                   for name in ("batch", "compare", "mcmc", "nlopt_fit"))

#: subcommand -> the library functions it calls with its options
CALLS = {
    "check": [brdf.properties.check],
    "synth": [brdf.gonioreflectometer.measure],
    "fit": [nlopt_fit.fit, mcmc.mcmc],
    "fit-images": [brdf.capture.fit_images, nlopt_fit.fit, mcmc.mcmc],
    "compare": [compare.compare, nlopt_fit.fit],
    "batch": [batch.batch, nlopt_fit.fit],
    "render": [brdf.render.render],
    "validate": [brdf.render.validate],
    "lobe": [brdf.viz.lobes.lobe_plotter],
    "demo": [brdf.demo.run],
    "precompile": [brdf.precompile.precompile],
}
#: options whose command-line default differs on purpose (none today)
DIFFERENT = set()


def _subcommands():
    parser = build_parser()
    action = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return action.choices


def _same(cli, library):
    if isinstance(library, tuple) and isinstance(cli, list):
        return list(library) == cli
    return cli == library and type(cli) is type(library)


@pytest.mark.parametrize("command", sorted(CALLS))
def test_cli_defaults_are_the_library_defaults(command):
    options = {a.dest: a.default for a in _subcommands()[command]._actions
               if a.default is not argparse.SUPPRESS}
    compared = 0
    for function in CALLS[command]:
        for name, parameter in inspect.signature(function).parameters.items():
            if name not in options or parameter.default is inspect.Parameter.empty:
                continue
            compared += 1
            cli, library = options[name], parameter.default
            if (command, name) in DIFFERENT:
                continue
            if isinstance(library, tuple) and cli == [] and library == ():
                continue
            # None on the command line: the option is not passed on, the library decides
            assert cli is None or _same(cli, library) or (cli == [] and library is None), \
                f"{command} --{name.replace('_', '-')}: {cli!r}, {function.__name__}: {library!r}"
    assert compared, f"no option of {command} matches a parameter of {CALLS[command]}"


def _shape(parser):
    """What a parser accepts and says: each action's options, destination, default, help and
    choices, and the same of each subcommand's parser."""
    shape = []
    for a in parser._actions:
        shape.append((tuple(a.option_strings), a.dest, repr(a.default), a.help, a.nargs,
                      a.required, getattr(a.type, "__name__", repr(a.type)), a.metavar))
        if isinstance(a, argparse._SubParsersAction):
            shape.append({name: _shape(p) for name, p in a.choices.items()})
    return shape


def test_a_parser_built_for_one_subcommand_parses_it_as_the_whole_parser_does():
    """The command line builds only the options of the subcommand it names
    (``build_parser(argv)``); that subcommand's parser must be the one the whole parser
    holds, and a word that names no subcommand gets the whole parser (which lists them)."""
    whole = _subcommands()
    for name in whole:
        for argv in ([name], ["--debug", name, "x"], ["--plugin", "p.py", "-q", name]):
            action = next(a for a in build_parser(argv)._actions
                          if isinstance(a, argparse._SubParsersAction))
            assert list(action.choices) == [name]
            assert _shape(action.choices[name]) == _shape(whole[name]), argv
    for argv in (["chek"], [], ["--plugin", "check"], ["-q"]):
        assert _shape(build_parser(argv)) == _shape(build_parser()), argv
