"""Sphinx configuration of the advgame documentation (furo theme, MyST Markdown pages).

Build: ``sphinx-build -W --keep-going -b html docs docs/_build/html`` (warnings are errors).
The API reference (``api.md``) is generated from the docstrings by autosummary, recursively
over the ``advgame`` package, into ``docs/_autosummary/`` (not kept in git).
"""

from __future__ import annotations

import importlib.metadata

project = "advgame"
author = "the advgame authors"
copyright = "the advgame authors"
release = importlib.metadata.version("advgame")
version = release

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.napoleon",
    "sphinx.ext.viewcode",
]

source_suffix = {".md": "markdown", ".rst": "restructuredtext"}
root_doc = "index"
templates_path = ["_templates"]
# Folders the benchmark and campaign scripts may leave inside the result folders (gitignored).
exclude_patterns = ["_build", "attacks/*/runs", "attacks/*/br", "**/.ipynb_checkpoints"]

# MyST: GitHub-style anchors for "page.md#a-heading" links, down to ### headings and one more,
# so that the same relative links work on GitHub and on this site.
myst_heading_anchors = 4

# The API reference: one page per module, each object documented where it is defined.
autosummary_generate = True
autosummary_imported_members = False
autodoc_default_options = {
    "members": True,
    "show-inheritance": True,
    "ignore-module-all": True,
}
autodoc_member_order = "bysource"
autodoc_typehints = "signature"
autodoc_preserve_defaults = True
autoclass_content = "class"

# Docstrings are Google style ("Args:", "Returns:", "Raises:"), and put names in single
# backticks (`Game`, `seed`): they render as inline code, not as cross-references, since most
# name an argument or an outside type (NumPy, torch, Gymnasium) that no inventory here resolves.
default_role = "code"
napoleon_google_docstring = True
napoleon_numpy_docstring = False
napoleon_use_ivar = True

html_theme = "furo"
html_title = f"advgame {release}"
