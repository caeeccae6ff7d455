"""``posekit ceiling camera|calibrate|simulate|learn-scene|track|demo``."""

__all__ = ["add_parser"]


def add_parser(sub):
    p = sub.add_parser("ceiling", help="x, y, heading of a ground robot from laser dots on the ceiling")
    verbs = p.add_subparsers(dest="verb", metavar="VERB")
    verbs.required = True
    from .ceiling_calibrate import add_calibrate_parser
    from .ceiling_camera import add_camera_parser
    from .ceiling_demo import add_demo_parser
    from .ceiling_scene import add_learn_scene_parser
    from .ceiling_simulate import add_simulate_parser
    from .ceiling_track import add_track_parser
    add_camera_parser(verbs)
    add_calibrate_parser(verbs)
    add_simulate_parser(verbs)
    add_learn_scene_parser(verbs)
    add_track_parser(verbs)
    add_demo_parser(verbs)
