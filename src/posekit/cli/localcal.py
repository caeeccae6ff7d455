"""``posekit localcal match|handeye|simulate|demo``."""

__all__ = ["add_parser"]


def add_parser(sub):
    p = sub.add_parser("localcal", help="look-then-move positioning of a long-reach manipulator "
                                        "with motion-based local calibration")
    verbs = p.add_subparsers(dest="verb", metavar="VERB")
    verbs.required = True
    from .localcal_handeye import add_handeye_parser
    from .localcal_match import add_match_parser
    from .localcal_simulate import add_demo_parser, add_simulate_parser
    add_match_parser(verbs)
    add_handeye_parser(verbs)
    add_simulate_parser(verbs)
    add_demo_parser(verbs)
