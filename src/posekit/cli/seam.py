"""``posekit seam simulate|study|demo|track|tune|design``."""

__all__ = ["add_parser"]


def add_parser(sub):
    p = sub.add_parser("seam", help="particle-filter 6-DoF tool pose relative to a weld seam "
                                    "from 2D laser seam trackers and robot kinematics")
    verbs = p.add_subparsers(dest="verb", metavar="VERB")
    verbs.required = True
    from .seam_simulate import add_demo_parser, add_simulate_parser
    from .seam_study import add_study_parser
    add_simulate_parser(verbs)
    add_study_parser(verbs)
    add_demo_parser(verbs)
    from .seam_design import add_design_parser
    from .seam_track import add_track_parser
    from .seam_tune import add_tune_parser
    add_track_parser(verbs)
    add_tune_parser(verbs)
    add_design_parser(verbs)
