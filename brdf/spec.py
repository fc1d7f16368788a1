"""The model spec language (docs/conventions.md §2).

::

    spec  := term ("+" term)*
    term  := NAME ["(" [arg ("," arg)*] ")"]
    arg   := [NAME "="] value
    value := NUMBER | "[" NUMBER ("," NUMBER)* "]" | NAME ["(" ... ")"]

A ``NAME`` value is a choice (``variant=gmd``) or a nested component (``fresnel=schlick(f0=0.04)``,
``fresnel=none``). Errors name the column and what was expected.
"""

import json
import re

from .arguments import shown
from .errors import SpecError

__all__ = ["parse", "parse_component", "from_dict", "component_from_dict", "from_json"]

# ASCII only: Python's \d and float() also take full-width and Arabic-Indic digits and
# underscores between digits, which a spec written out by a program never holds
_TOKEN = re.compile(r"""
    (?P<ws>[ \t\r\n]+)
  | (?P<number>[-+]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][-+]?[0-9]+)?|[-+]?inf\b|nan\b)
  | (?P<name>[A-Za-z_][A-Za-z0-9_\-]*)
  | (?P<punct>[()\[\],=+])
""", re.VERBOSE | re.ASCII)
#: What may follow a number: a separator, never more of a word or another point
_AFTER_NUMBER = re.compile(r"[A-Za-z0-9_.]", re.ASCII)


def _tokens(text):
    pos, out = 0, []
    while pos < len(text):
        m = _TOKEN.match(text, pos)
        if m is None:
            char = text[pos]
            hint = (" (numbers take the ASCII digits 0-9 only)" if char.isdigit()
                    or char.isnumeric() else "")
            raise SpecError(f"spec column {pos + 1}: unexpected character {char!r}{hint} "
                            f"in {text!r}")
        if m.lastgroup == "number" and _AFTER_NUMBER.match(text, m.end()):
            end = m.end()
            while end < len(text) and (text[end].isalnum() or text[end] in "_."):
                end += 1
            raise SpecError(f"spec column {pos + 1}: malformed number {text[pos:end]!r}; "
                            f"expected a number such as 1000, 0.5 or 1e-3 in {text!r}")
        if m.lastgroup != "ws":
            out.append((m.lastgroup, m.group(), pos))
        pos = m.end()
    out.append(("end", "", len(text)))
    return out


class _Parser:
    def __init__(self, text):
        self.text, self.toks, self.i = text, _tokens(text), 0

    def peek(self):
        return self.toks[self.i]

    def take(self, kind=None, value=None):
        tok = self.toks[self.i]
        if (kind and tok[0] != kind) or (value and tok[1] != value):
            self.fail(tok, f"expected {value or kind}")
        self.i += 1
        return tok

    def fail(self, tok, expected):
        got = "end of spec" if tok[0] == "end" else repr(tok[1])
        raise SpecError(f"spec column {tok[2] + 1}: {expected}, got {got} in {self.text!r}")

    def spec(self, registry):
        terms = [self.term(registry)]
        while self.peek()[1] == "+":
            self.take()
            terms.append(self.term(registry))
        self.take("end")
        return terms

    def term(self, registry):
        tok = self.take("name")
        try:
            cls = registry.get(tok[1])
        except SpecError as exc:
            raise SpecError(f"spec column {tok[2] + 1}: {exc}") from None
        args, kwargs, seen = [], {}, set()
        if self.peek()[1] == "(":
            self.take()
            while self.peek()[1] != ")":
                if self.peek()[0] == "name" and self.toks[self.i + 1][1] == "=":
                    key = self.take()
                    self.take(value="=")
                    decl = self.declaration(cls, key)
                    if decl.name in seen:
                        raise SpecError(f"spec column {key[2] + 1}: {cls.name}: {decl.name} is "
                                        f"given twice in {self.text!r}")
                    seen.add(decl.name)
                    kwargs[key[1]] = self.value(decl)
                elif kwargs:
                    self.fail(self.peek(), "expected NAME=value after a named argument")
                else:
                    decl = cls.PARAMS[len(args)] if len(args) < len(cls.PARAMS) else None
                    if decl is not None:
                        seen.add(decl.name)
                    args.append(self.value(decl))
                if self.peek()[1] != ")":
                    self.take(value=",")
            self.take(value=")")
        try:
            return cls(*args, **kwargs)
        except SpecError as exc:  # keep the subclass (ParameterError) for callers to catch
            raise type(exc)(f"spec column {tok[2] + 1}: {exc}") from None

    def declaration(self, cls, key):
        try:
            return cls.declaration(key[1])
        except SpecError as exc:
            raise SpecError(f"spec column {key[2] + 1}: {exc}") from None

    def value(self, decl):
        """A number, a [list], a choice name, or a nested term parsed in place (so that its
        errors point at their own column)."""
        from .models import Nested
        tok = self.peek()
        if isinstance(decl, Nested) and tok[0] == "name":
            return self.term(decl.registry)
        if tok[0] == "number":
            self.take()
            return float(tok[1])
        if tok[1] == "[":
            self.take()
            items = [float(self.take("number")[1])]
            while self.peek()[1] == ",":
                self.take()
                items.append(float(self.take("number")[1]))
            self.take(value="]")
            return items
        if tok[0] == "name":
            if decl is not None and decl.kind == "number":
                self.fail(tok, f"{decl.name} expects a number or a [list]")
            self.take()
            return tok[1]
        self.fail(tok, "expected a number, a [list] or a name")


def parse(text):
    """Parse a spec such as ``"lambert(albedo=0.8) + ggx(alpha=0.2)"`` into a model.

    A model instance is returned unchanged, so functions can take either.
    """
    from .models import MODELS, Model, Sum
    if isinstance(text, Model):
        return text
    if not isinstance(text, str) or not text.strip():
        raise SpecError(f"a model spec must be a non-empty string, got {text!r}")
    terms = _Parser(text).spec(MODELS)
    return terms[0] if len(terms) == 1 else Sum(terms)


def parse_component(text, registry):
    """Parse a single component (e.g. a Fresnel term) of ``registry`` from its spec text."""
    terms = _Parser(text).spec(registry)
    if len(terms) != 1:
        raise SpecError(f"expected one {registry.what}, got {text!r}")
    return terms[0]


def from_dict(d):
    """Model from :meth:`~brdf.models.base.Component.to_dict` output."""
    from .models import MODELS, Sum
    if isinstance(d, dict) and "sum" in d:
        lobes = d["sum"]
        if not isinstance(lobes, list) or not all(isinstance(x, dict) and "sum" not in x
                                                  for x in lobes):
            raise SpecError(f"a sum's 'sum' must be a list of model descriptions "
                            f"{{\"model\": name, \"params\": {{...}}}}, got {shown(lobes)}")
        return Sum([component_from_dict(x, MODELS) for x in lobes])
    return component_from_dict(d, MODELS)


def component_from_dict(d, registry):
    """A component of ``registry`` from ``{"model": name, "params": {name: value}}``."""
    if not isinstance(d, dict):
        raise SpecError(f"a {registry.what} description must be an object, got "
                        f"{type(d).__name__}")
    if "model" not in d:
        raise SpecError(f"a {registry.what} description needs a 'model'" +
                        (" or 'sum' key" if registry.what == "model" else " key"))
    name, params = d["model"], d.get("params", {})
    if not isinstance(name, str):
        raise SpecError(f"a {registry.what} description's 'model' must be a name, got "
                        f"{shown(name)}")
    if not (isinstance(params, dict) and all(isinstance(k, str) for k in params)):
        raise SpecError(f"{name}: 'params' must be an object {{name: value}}, got "
                        f"{shown(params)}")
    return registry.get(name)(**params)


def from_json(text):
    """Model from a JSON string written by ``json.dumps(model.to_dict())``."""
    if not isinstance(text, (str, bytes, bytearray)):
        raise SpecError(f"model JSON must be text, got {type(text).__name__}")
    try:
        document = json.loads(text)
    except json.JSONDecodeError as exc:
        raise SpecError(f"model JSON line {exc.lineno} column {exc.colno}: {exc.msg}") from None
    except UnicodeDecodeError as exc:
        raise SpecError(f"model JSON byte {exc.start}: not UTF-8 text") from None
    except RecursionError:
        raise SpecError("model JSON: nested too deeply to be a model description") from None
    return from_dict(document)
