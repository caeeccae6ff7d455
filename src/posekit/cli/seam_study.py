"""Placeholder: filled in by the seam_study work (issue 5/6)."""

from ..errors import ConfigError


def add_study_parser(verbs):
    p = verbs.add_parser("study", help="(not implemented yet)")
    p.set_defaults(func=_missing)


def _missing(args):
    raise ConfigError("this command is not implemented yet")
