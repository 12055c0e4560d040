"""Sphinx configuration of the haptic_bus manual: ``python -m sphinx -W -b html docs OUT``.

The pages are Markdown (myst-parser) beside three reStructuredText pages that generate their
content at build time: the API reference (autodoc, from the docstrings), the command reference
(sphinx-argparse, from the argparse parsers) and the error tree (``_ext/error_tree.py``, from the
class hierarchy).  The package is imported from this source tree, installed or not.
"""

from __future__ import annotations

import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parent
sys.path[:0] = [str(DOCS.parent), str(DOCS / "_ext")]  # this tree's packages, then the local extension

from haptic_bus import __version__  # noqa: E402  (after the path is set)

project = "haptic_bus"
author = "the haptic_bus authors"
copyright = "the haptic_bus authors"
version = release = __version__

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinxarg.ext",
    "error_tree",
]
source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
exclude_patterns = ["_build", "performance/bench.md"]  # bench.md is included by performance.md, not a page of its own
myst_heading_anchors = 3  # "[...](page.md#a-section)" links to a section by its title
myst_enable_extensions = ["colon_fence"]

autodoc_member_order = "bysource"
autodoc_typehints = "signature"
autodoc_preserve_defaults = True  # a default as the source spells it (DEFAULT_TPDO_WITH_POSITION), not its repr
autodoc_default_options = {"members": True, "show-inheritance": True}

smartquotes = False  # "--smoke" stays two hyphens, as typed
html_theme = "alabaster"
html_title = f"haptic_bus {release}"
html_theme_options = {"page_width": "1150px", "sidebar_width": "230px"}
