"""Placeholder: filled in by the localcal_match work (issue 5/6)."""

from ..errors import ConfigError


def add_match_parser(verbs):
    p = verbs.add_parser("match", help="(not implemented yet)")
    p.set_defaults(func=_missing)


def _missing(args):
    raise ConfigError("this command is not implemented yet")
