"""Tables of things by name: the one helper behind every "pick it by name" of pafp (docs/registries.md).

A :class:`Registry` maps a name to a ``"module:attribute"`` reference that is imported only when the name
is used, as python-can picks an interface and pyserial a URL handler: listing the names imports nothing,
and a table that names a class of a higher layer does not import it. An unknown name is a ValueError that
names the value, where it came from and the choices. A registry with an entry-point ``group`` also lists
the entry points of that group of every installed distribution, so a separate package adds a device, a
controller or a link by declaring, in its own ``pyproject.toml``::

    [project.entry-points."pafp.devices"]
    my-imu = "my_package.imu:MODEL"

with no edit to pafp's files; :meth:`Registry.register` does the same at run time (a test, a script).
The registry lives in the layer whose objects it names (hal/ is below everything, so every layer may
import this helper).

>>> shapes = Registry("shape", {"circle": "math:pi"})
>>> shapes.names(), shapes.load("circle") > 3
(['circle'], True)
>>> shapes.load("square", "--shape")
Traceback (most recent call last):
...
ValueError: --shape 'square' unknown: one of ['circle']
"""

from __future__ import annotations

import functools
import importlib
import importlib.metadata
import re
from collections.abc import Iterator, Mapping
from typing import Any

__all__ = ["Registry", "resolve"]

_REF = re.compile(r"[A-Za-z_][\w.]*(:[A-Za-z_][\w.]*)?")


def resolve(ref: str) -> Any:
    """What a ``"module:attribute"`` reference names (dotted attributes allowed; ``"module"``: the module)."""
    module, _, attr = ref.partition(":")
    value: Any = importlib.import_module(module)
    for part in attr.split(".") if attr else ():
        value = getattr(value, part)
    return value


@functools.cache
def _entry_points() -> dict[str, list[tuple[str, str]]]:
    """Every installed entry point of a ``pafp.*`` group, by group (read once per process)."""
    groups: dict[str, dict[str, str]] = {}
    for dist in importlib.metadata.distributions():  # in sys.path order: the first of a name wins, as imports
        for ep in dist.entry_points:
            if ep.group.startswith("pafp."):
                groups.setdefault(ep.group, {}).setdefault(ep.name, ep.value)
    return {group: list(entries.items()) for group, entries in groups.items()}


class Registry:
    """Names -> lazily imported ``"module:attribute"`` (or ``"module"``) references, or the objects themselves.

    ``what`` names the kind of thing in error messages ("motor link", "device", ...); ``group`` is the
    optional entry-point group read once, on first use; an entry point never replaces a shipped entry (it is
    skipped, and listed in :attr:`shadowed`).
    """

    def __init__(self, what: str, entries: Mapping[str, object], *, group: str | None = None) -> None:
        """A registry of the shipped entries (name -> ``"module:attribute"``, or the object itself)."""
        self.what = what
        self.group = group
        self._entries: dict[str, object] = {}
        self._loaded: dict[str, object] = {}
        self._group_read = group is None
        self._from_group: list[str] = []
        self.shadowed: list[str] = []
        """Entry points of ``group`` skipped because a shipped or registered name already had their name."""
        for name, ref in entries.items():
            self._add(name, ref, replace=False)
        self._shipped = tuple(self._entries)

    # ----------------------------------------------------------------- entries
    def _add(self, name: str, target: object, *, replace: bool) -> None:
        if not isinstance(name, str) or not name or name != name.strip():
            raise ValueError(f"{self.what} name {name!r} invalid: a non-empty string without surrounding blanks")
        if isinstance(target, str) and not _REF.fullmatch(target):
            raise ValueError(f"{self.what} {name!r}: reference {target!r} is not 'module:attribute' or 'module'")
        if name in self._entries and not replace:
            raise ValueError(f"{self.what} {name!r} already registered; pass replace=True to override")
        self._entries[name] = target
        self._loaded.pop(name, None)

    def _read_group(self) -> None:
        if self._group_read:
            return
        self._group_read = True
        for name, value in _entry_points().get(str(self.group), []):
            if name in self._entries:
                self.shadowed.append(name)
            else:
                self._entries[name] = value
                self._from_group.append(name)

    def refresh(self) -> None:
        """Read the entry-point group again (after a package was installed or its folder put on sys.path)."""
        for name in self._from_group:
            self._entries.pop(name, None)
            self._loaded.pop(name, None)
        self._from_group, self.shadowed = [], []
        _entry_points.cache_clear()
        self._group_read = self.group is None

    def register(self, name: str, target: object, *, replace: bool = False) -> None:
        """Add name -> target (a ``"module:attribute"`` string, imported on first use, or the object itself)."""
        self._read_group()
        self._add(name, target, replace=replace)

    def unregister(self, name: str) -> None:
        """Remove name (a shipped entry too); ValueError if it is not registered."""
        self._read_group()
        if self._entries.pop(name, None) is None:
            raise ValueError(f"{self.what} {name!r} not registered: one of {sorted(self.names())}")
        self._loaded.pop(name, None)

    # ------------------------------------------------------------------ lookup
    def names(self) -> list[str]:
        """Every name: the shipped ones in their table's order, then those added (entry points, register)."""
        self._read_group()
        return list(self._entries)

    def __contains__(self, name: object) -> bool:
        self._read_group()
        return name in self._entries

    def __iter__(self) -> Iterator[str]:
        return iter(self.names())

    def __len__(self) -> int:
        return len(self.names())

    def shipped(self) -> list[str]:
        """The names of the table the registry was made with (pafp's own), as far as they are still registered."""
        names = self.names()
        return [n for n in self._shipped if n in names]

    def added(self) -> list[str]:
        """The names not shipped: entry points of plug-ins and registered ones."""
        return [n for n in self.names() if n not in self._shipped]

    def by_origin(self) -> str:
        """The names for a help text, by where they come from: ``"a or b (shipped); x (plug-in)"``."""
        shipped, added = self.shipped(), self.added()
        parts = [f"{self.spoken(names=shipped)} (shipped)"] if shipped else []
        if added:
            parts.append(f"{self.spoken(names=added)} (plug-in{'s' if len(added) > 1 else ''})")
        return "; ".join(parts) or "none registered"

    def spoken(self, last: str = "or", names: list[str] | None = None) -> str:
        """The names (default: all) as a phrase for help texts: ``"a, b or c"``."""
        names = self.names() if names is None else names
        return names[0] if len(names) == 1 else f"{', '.join(names[:-1])} {last} {names[-1]}"

    def check(self, name: object, where: str | None = None) -> str:
        """name if it is registered; ValueError ``"<where> <name> unknown: one of [...]"`` otherwise."""
        if not isinstance(name, str) or name not in self:
            raise ValueError(f"{where or self.what} {name!r} unknown: one of {sorted(self.names())}")
        return name

    def reference(self, name: str, where: str | None = None) -> str:
        """The ``"module:attribute"`` of name ("module.qualname" of an object registered as itself)."""
        target = self._entries[self.check(name, where)]
        if isinstance(target, str):
            return target
        return f"{getattr(target, '__module__', '?')}:{getattr(target, '__qualname__', type(target).__name__)}"

    def load(self, name: str, where: str | None = None) -> Any:
        """The object name refers to, imported on first use; ValueError naming where and the choices."""
        self.check(name, where)
        if name not in self._loaded:
            target = self._entries[name]
            if isinstance(target, str):
                try:
                    target = resolve(target)
                except (ImportError, AttributeError) as exc:
                    raise ValueError(f"{where or self.what} {name!r}: {target!r} cannot be loaded: "
                                     f"{type(exc).__name__}: {exc}") from None
            self._loaded[name] = target
        return self._loaded[name]

    def __repr__(self) -> str:
        return f"Registry({self.what!r}, {len(self._entries)} entries, group={self.group!r})"
