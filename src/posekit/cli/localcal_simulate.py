"""Placeholder: filled in by the localcal_simulate work (issue 5/6)."""

from ..errors import ConfigError


def add_simulate_parser(verbs):
    p = verbs.add_parser("simulate", help="(not implemented yet)")
    p.set_defaults(func=_missing)

def add_demo_parser(verbs):
    p = verbs.add_parser("demo", help="(not implemented yet)")
    p.set_defaults(func=_missing)


def _missing(args):
    raise ConfigError("this command is not implemented yet")
