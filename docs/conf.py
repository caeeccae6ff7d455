"""Sphinx configuration of the posekit documentation (``sphinx-build -W --keep-going docs docs/_build/html``)."""

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))        # document this tree, not an installed copy

import posekit  # noqa: E402

project = "posekit"
author = "the posekit authors"
copyright = "the posekit authors, MIT licence"
version = release = posekit.__version__

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.mathjax",
    "numpydoc",
    "myst_parser",
    "sphinxarg.ext",
]
source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
root_doc = "index"
exclude_patterns = ["_build"]
myst_enable_extensions = ["colon_fence", "dollarmath"]
myst_heading_anchors = 3

# The API reference: what each package's __all__ lists, in source order, from its real home.
autodoc_default_options = {"members": True, "member-order": "bysource"}
autodoc_typehints = "none"              # the numpydoc sections give types, shapes and units
autodoc_mock_imports = []
numpydoc_show_class_members = False     # autodoc's :members: lists them once
numpydoc_class_members_toctree = False
numpydoc_xref_param_type = False
numpydoc_validation_checks = set()

html_theme = "furo"
html_title = f"posekit {release}"
html_static_path = []

# argparse help text is shown as typed: "--out" must not become an en dash
smartquotes = False
# docs/notes/issue-*.md are written by every engineer and folded in by a glob: a note that starts at
# "##", or links to a file outside the site, must not break the build (the links stay plain text).
myst_ref_domains = ["std", "py"]
suppress_warnings = ["myst.header", "myst.xref_missing", "image.not_readable"]


def _title_notes(app, docname, source):
    """A note without a heading gets one from its file name ("notes/issue-27b" -> "Issue 27b")."""
    if docname.startswith("notes/") and not any(line.startswith("#") for line in source[0].splitlines()):
        source[0] = f"# {docname.split('/', 1)[1].replace('-', ' ').capitalize()}\n\n" + source[0]


def setup(app):
    app.connect("source-read", _title_notes)
