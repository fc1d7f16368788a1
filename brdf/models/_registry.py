"""Registries of named components: BRDF model families and Fresnel terms.

As in colour-science, a family is a plain class registered under a name and aliases; the spec
parser, ``brdf-fit models`` and JSON loading look names up here.
"""

from ..errors import SpecError


class Registry:
    """Name -> class, with aliases; lookups of unknown names list the valid ones."""

    def __init__(self, what, hint=""):
        self.what, self.hint = what, hint
        self._classes = {}
        self._aliases = {}

    def register(self, cls):
        """Class decorator: add ``cls`` under ``cls.name`` and ``cls.aliases``."""
        for key in (cls.name, *cls.aliases):
            if key in self._aliases and self._aliases[key] != cls.name:
                raise ValueError(f"{self.what} name {key!r} is already registered")
            self._aliases[key] = cls.name
        self._classes[cls.name] = cls
        return cls

    def unregister(self, name):
        """Remove the class registered as ``name`` and its aliases; returns it."""
        cls = self.get(name)
        del self._classes[cls.name]
        for key in [k for k, v in self._aliases.items() if v == cls.name]:
            del self._aliases[key]
        return cls

    def owner(self, key):
        """The class registered under the name or alias ``key``, or None."""
        name = self._aliases.get(key)
        return None if name is None else self._classes[name]

    def get(self, name):
        key = self._aliases.get(name)
        if key is None:
            raise SpecError(f"unknown {self.what} {name!r}; valid: {', '.join(self.names())}"
                            f"{self.hint}")
        return self._classes[key]

    def names(self):
        return list(self._classes)

    def classes(self):
        return list(self._classes.values())

    def __contains__(self, name):
        return name in self._aliases


MODELS = Registry("model", " (a custom family must be registered first: import its module, "
                           "or brdf-fit --plugin FILE)")
FRESNEL = Registry("Fresnel term")
register = MODELS.register
