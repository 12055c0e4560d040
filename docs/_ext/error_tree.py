"""The ``error-tree`` directive: every error class of the distribution as one text tree, drawn at
build time from the class hierarchy (no hand-kept copy to drift).

The roots are the classes of ``haptic_bus.errors`` and ``drives.errors`` that derive from no
error of ours: one, ``HapticBusError`` (defined in ``drives.errors``).  Every module of
``haptic_bus``, ``drives`` and ``sim_drive`` is imported first, so that the errors defined beside
the code that raises them are subclasses Python knows of; the test and bench tooling
(``haptic_bus.testing``, ``haptic_bus.bench``) is left out, since its extras may be absent where
the manual is built.  A class is drawn under its first base (its MRO's next error of ours); its
other bases follow its name in parentheses, its module and the first line of its docstring after it.
"""

from __future__ import annotations

import importlib
import inspect
import pkgutil
import re
from typing import Any

from docutils import nodes
from sphinx.application import Sphinx
from sphinx.util.docutils import SphinxDirective

PACKAGES = ("haptic_bus", "drives", "sim_drive")
LEFT_OUT = ("haptic_bus.testing", "haptic_bus.bench")  # tooling with extras of its own; it defines no error
HOMES = ("haptic_bus.errors", "drives.errors")


def _ours(cls: type) -> bool:
    """True for a class defined in one of the three packages."""
    return cls.__module__.split(".")[0] in PACKAGES


def _our_error(cls: type) -> bool:
    return _ours(cls) and issubclass(cls, BaseException)


def _import_every_module() -> None:
    for name in PACKAGES:
        package = importlib.import_module(name)
        for module in pkgutil.walk_packages(package.__path__, f"{name}."):
            if module.name.endswith(".__main__") or module.name.startswith(LEFT_OUT):
                continue
            importlib.import_module(module.name)


def roots() -> list[type[BaseException]]:
    """The error classes of the two error modules that derive from no error of ours, in source order."""
    found: list[type[BaseException]] = []
    for home in HOMES:
        module = importlib.import_module(home)
        for _, cls in inspect.getmembers(module, inspect.isclass):
            if cls.__module__ == home and issubclass(cls, BaseException) and not any(map(_our_error, cls.__bases__)):
                found.append(cls)
    return sorted(found, key=lambda cls: (HOMES.index(cls.__module__), inspect.getsourcelines(cls)[1]))


def _parent(cls: type) -> type | None:
    """The error of ours that ``cls`` is drawn under: its first base that is one."""
    return next(filter(_our_error, cls.__bases__), None)


def _label(cls: type) -> str:
    others = [base.__name__ for base in cls.__bases__  # a second parent of ours, or a builtin one but the plain root
              if base is not _parent(cls) and issubclass(base, BaseException) and base not in (Exception, BaseException)]
    return cls.__name__ + (f" ({', '.join(others)})" if others else "")


def _summary(cls: type) -> str:
    """The first sentence of the class's own docstring (none for a class without one)."""
    doc = " ".join((cls.__doc__ or "").split())
    doc = re.sub(r":\w+:`~?(?:[\w.]*\.)?(\w+)`", r"\1", doc).replace("``", "")  # roles and literals as plain text
    return re.split(r"(?<!e\.g)(?<!i\.e)\.(?:\s|$)", doc)[0]


def _children(cls: type) -> list[type]:
    subclasses = (sub for sub in cls.__subclasses__() if _our_error(sub) and _parent(sub) is cls)
    return sorted(subclasses, key=lambda sub: (sub.__module__ not in HOMES, sub.__module__, sub.__name__))


def _draw(cls: type, prefix: str, branch: str, rows: list[tuple[str, str, str]]) -> None:
    """``cls`` and everything below it; ``prefix`` the columns of its ancestors, ``branch`` its own."""
    rows.append((prefix + branch + _label(cls), cls.__module__, _summary(cls)))
    below = _children(cls)
    for i, child in enumerate(below):
        last = i == len(below) - 1
        _draw(child, prefix + ("" if not branch else ("      " if branch.startswith(" `") else " |    ")),
              " `-- " if last else " +-- ", rows)


def tree_lines() -> list[tuple[str, str, str]]:
    """(tree column, module, summary) per class, every root's tree in turn, a blank row between."""
    _import_every_module()
    rows: list[tuple[str, str, str]] = []
    for root in roots():
        if rows:
            rows.append(("", "", ""))
        _draw(root, "", "", rows)
    return rows


def tree_text() -> str:
    """The tree as aligned text: the classes, their modules, the first line of each docstring."""
    rows = tree_lines()
    width = max(len(tree) for tree, _, _ in rows) + 2
    module_width = max(len(module) for _, module, _ in rows) + 2
    return "\n".join(f"{tree:<{width}}{module:<{module_width}}{summary}".rstrip() for tree, module, summary in rows)


class ErrorTree(SphinxDirective):
    """``.. error-tree::`` becomes a literal block holding :func:`tree_text`."""

    has_content = False

    def run(self) -> list[nodes.Node]:
        text = tree_text()
        block = nodes.literal_block(text, text)
        block["language"] = "text"
        return [block]


def setup(app: Sphinx) -> dict[str, Any]:
    app.add_directive("error-tree", ErrorTree)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
