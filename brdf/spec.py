"""The model spec language (DESIGN.md section 2).

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

from .errors import SpecError

__all__ = ["parse", "parse_component", "from_dict", "from_json"]

_TOKEN = re.compile(r"""
    (?P<ws>\s+)
  | (?P<number>[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?|[-+]?inf\b|nan\b)
  | (?P<name>[A-Za-z_][A-Za-z0-9_\-]*)
  | (?P<punct>[()\[\],=+])
""", re.VERBOSE)


def _tokens(text):
    pos, out = 0, []
    while pos < len(text):
        m = _TOKEN.match(text, pos)
        if m is None:
            raise SpecError(f"spec column {pos + 1}: unexpected character {text[pos]!r} "
                            f"in {text!r}")
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
        args, kwargs = [], {}
        if self.peek()[1] == "(":
            self.take()
            while self.peek()[1] != ")":
                if self.peek()[0] == "name" and self.toks[self.i + 1][1] == "=":
                    key = self.take()
                    self.take(value="=")
                    kwargs[key[1]] = self.value(self.declaration(cls, key))
                elif kwargs:
                    self.fail(self.peek(), "expected NAME=value after a named argument")
                else:
                    decl = cls.PARAMS[len(args)] if len(args) < len(cls.PARAMS) else None
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
    if not isinstance(d, dict):
        raise SpecError(f"a model description must be an object, got {type(d).__name__}")
    if "sum" in d:
        return Sum([from_dict(x) for x in d["sum"]])
    if "model" not in d:
        raise SpecError("a model description needs a 'model' or 'sum' key")
    return MODELS.get(d["model"])(**dict(d.get("params", {})))


def from_json(text):
    """Model from a JSON string written by ``json.dumps(model.to_dict())``."""
    try:
        return from_dict(json.loads(text))
    except json.JSONDecodeError as exc:
        raise SpecError(f"model JSON line {exc.lineno} column {exc.colno}: {exc.msg}") from None
