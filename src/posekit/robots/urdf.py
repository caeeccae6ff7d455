"""A user's own robot from a URDF file: the base→tip path as a :class:`SerialChain`.

The file is read as the world writes it: any plain URDF that Pinocchio reads loads. posekit
checks it is well-formed XML, keeps the ``<link>`` and ``<joint>`` elements of the ``<robot>``
(everything else — ``<gazebo>``, ``<transmission>``, plugins, materials, visual and collision
geometry, comments — is ignored) and parses those with yourdfpy (a maintained URDF parser).
It then takes the path of joints from ``base_link`` down to ``tip_link``, folds fixed joints
into the next joint's origin (or into the flange after the last moving joint), and keeps every
moving joint's axis, limits and name. Joints off that path (grippers, cameras, the passive
cylinders of a parallel-link arm) are ignored. URDF lengths are metres and are converted to mm;
a prismatic joint's variable is then in mm.

Without ``tip_link`` the chain is the arm (:mod:`._urdf_tree`): its tip is the last link that
the arm's end effectors hang from — a gripper's fingers, mimic joints and fixed sensor frames
are left out — and where the tree offers two equal arms, a one-line error names the candidate
tips. The chain says what was chosen (``repr``, :attr:`SerialChain.notes`).

Refused in one line: xacro (an element or attribute of the xacro namespace, or ``${...}`` /
``$(...)`` in a link or joint attribute; the same text in a comment is fine), DTD entities,
mimic, floating or planar joints on the chain, closed loops, a joint origin beyond
:data:`MAX_ORIGIN_M` or not finite. A joint limit of ±inf (``lower="-inf"``) is read as
unbounded, and the chain's notes say so.
"""

import copy
import io
import math
from pathlib import Path

import numpy as np

from posekit.errors import ConfigError
from posekit.io import quote

from ._urdf_tree import JointTree, _names
from .chain import PRISMATIC, REVOLUTE, SerialChain

__all__ = ["MAX_ORIGIN_M", "MAX_URDF_BYTES", "load_urdf"]

#: Largest URDF file read (bytes); real descriptions are 10 kB – 1 MB.
MAX_URDF_BYTES = 16 * 1024 * 1024
#: Largest joint origin offset accepted, m (10 km: beyond it the numbers are not metres of a
#: robot, and 1e300 m would overflow once squared).
MAX_ORIGIN_M = 1e4

_MOVING = {"revolute": REVOLUTE, "continuous": REVOLUTE, "prismatic": PRISMATIC}
_M_TO_MM = 1000.0
#: Attribute text that only xacro gives meaning to (an expression or a substitution argument).
_XACRO_TEXT = ("${", "$(")


def _is_xacro_name(tag: str) -> bool:
    """A tag or attribute name in the xacro namespace (``{...xacro}name`` or ``xacro:name``)."""
    return tag.startswith("xacro:") or (tag.startswith("{") and "xacro" in tag[1:tag.find("}")].lower())


def _parse_xml(path: Path, data: bytes):
    """The root element of well-formed XML, or a ConfigError.

    An undeclared namespace prefix (``<sensor:camera>`` in an old gazebo block) is a namespace
    error, not a syntax error: urdfdom and Pinocchio read such files, so they are read here too.
    """
    from posekit._extras import require

    etree = require("lxml.etree", "urdf", f"reading the URDF file {path.name}")
    parser = etree.XMLParser(resolve_entities=False, no_network=True, huge_tree=False)
    try:
        return etree.fromstring(data, parser)
    except etree.XMLSyntaxError as exc:
        errors = list(parser.error_log)                 # this parse's own log (exc's may hold older ones)
        if errors and all(e.domain == etree.ErrorDomains.NAMESPACE for e in errors):
            lenient = etree.XMLParser(resolve_entities=False, no_network=True, huge_tree=False, recover=True)
            root = etree.fromstring(data, lenient)
            if root is not None:
                return root
        msg = " ".join(str(exc).split())
        raise ConfigError(f"{path}: malformed XML: {msg[:160]}; expected a URDF file") from None


def _read_xml(path: Path) -> bytes:
    """The kinematic part of the file (``<robot>`` with its links and joints) as XML bytes, after
    the checks every reader makes: exists, size, well-formed XML, a URDF, no xacro."""
    from posekit.io import read_bytes

    if not path.exists():
        raise ConfigError(f"{path}: no such URDF file")
    data = read_bytes(path, expected="a URDF file", error=ConfigError, limit=MAX_URDF_BYTES)
    if b"<!ENTITY" in data:
        raise ConfigError(f"{path}: unsupported URDF: DTD entities; expected plain XML (expand xacro first)")
    root = _parse_xml(path, data)
    if root.tag != "robot":
        raise ConfigError(f"{path}: root element <{str(root.tag)[:40]}>; expected a URDF <robot> element")
    for el in root.iter():
        tag = el.tag if isinstance(el.tag, str) else ""     # comments and processing instructions
        if tag and (_is_xacro_name(tag) or any(_is_xacro_name(a) for a in el.attrib)):
            raise ConfigError(f"{path}: a xacro file (element <{tag.split('}')[-1][:40]}> of the xacro namespace); "
                              "expected plain URDF (run xacro first)")
    out = root.makeelement("robot", {"name": root.get("name", "")})
    for k, el in enumerate(root.iterchildren("link", "joint")):
        if not el.get("name"):
            raise ConfigError(f"{path}: <{el.tag}> number {k + 1} of <robot> has no name attribute; "
                              "expected name=\"...\"")
        for sub in el.iter():
            for value in sub.attrib.values():
                if any(x in value for x in _XACRO_TEXT):
                    raise ConfigError(f"{path}: a xacro file ({el.tag} '{el.get('name')[:40]}' has the expression "
                                      f"'{value[:40]}'); expected plain URDF (run xacro first)")
        for sub in el.iter("origin", "axis", "limit", "mimic"):   # numbers by value: not '١٢' or '1_0'
            for key, value in sub.attrib.items():
                if key != "joint" and (not value.isascii() or "_" in value):
                    raise ConfigError(f"{path}: <{sub.tag}> {key}={quote(value, 40)}: expected plain decimal "
                                      "numbers")
        if el.tag == "link":
            out.append(out.makeelement("link", {"name": el.get("name")}))
        else:
            joint = copy.deepcopy(el)
            for child in list(joint):
                if not isinstance(child.tag, str):
                    joint.remove(child)
            out.append(joint)
    from lxml import etree

    return etree.tostring(out)


def _parse(path: Path, data: bytes):
    """The yourdfpy model of the kinematic XML, or a ConfigError naming the element."""
    import contextlib

    from posekit._extras import require

    yourdfpy = require("yourdfpy", "urdf", f"reading the URDF file {path.name}")

    try:
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
            return yourdfpy.URDF.load(
                io.BytesIO(data), load_meshes=False, build_scene_graph=False,
                build_collision_scene_graph=False, load_collision_meshes=False,
            )
    except (ValueError, TypeError, KeyError, AttributeError, IndexError, OverflowError) as exc:
        raise ConfigError(f"{path}: malformed URDF ({type(exc).__name__}: {str(exc)[:120]}); "
                          "expected <joint> elements with parent, child, origin xyz/rpy of 3 numbers") from None


def _origin(path: Path, j) -> np.ndarray:
    """Joint ``j``'s origin as a (4, 4) transform in mm, or a ConfigError."""
    T = np.eye(4) if j.origin is None else np.array(j.origin, dtype=np.float64)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise ConfigError(f"{path}: joint '{j.name}': origin xyz/rpy must be 3 finite numbers each")
    far = float(np.abs(T[:3, 3]).max())
    if far > MAX_ORIGIN_M:
        raise ConfigError(f"{path}: joint '{j.name}': origin xyz {far:.3g} m from its parent; expected metres "
                          f"within {MAX_ORIGIN_M:g} m")
    T = T.copy()
    T[:3, 3] *= _M_TO_MM
    return T


def _axis(path: Path, j) -> np.ndarray:
    """Joint ``j``'s unit axis (x when the file gives none), or a ConfigError."""
    axis = np.array([1.0, 0.0, 0.0] if j.axis is None else j.axis, dtype=np.float64)
    big = float(np.abs(axis).max()) if axis.shape == (3,) and np.all(np.isfinite(axis)) else 0.0
    if big == 0.0 or np.linalg.norm(axis / big) < 1e-12:
        raise ConfigError(f"{path}: joint '{j.name}': axis {axis.tolist()}; expected a non-zero direction")
    axis = axis / big                                   # 1e300 components do not overflow the norm
    return axis / np.linalg.norm(axis)


def _limits(path: Path, j, scale: float, notes: list) -> tuple[float, float]:
    """``(lower, upper)`` of joint ``j`` in rad or mm; ±inf read as unbounded (and noted)."""
    limit = j.limit
    if j.type == "continuous" or limit is None:
        return -math.inf, math.inf
    low = -math.inf if limit.lower is None else float(limit.lower) * scale
    up = math.inf if limit.upper is None else float(limit.upper) * scale
    if math.isnan(low) or math.isnan(up) or not low <= up:
        raise ConfigError(f"{path}: joint '{j.name}': limit lower {low:g} > upper {up:g} (or NaN); "
                          "expected lower <= upper")
    if math.isinf(low) or math.isinf(up):
        notes.append(f"joint '{j.name}': limit {low:g}..{up:g} read as unbounded")
    return low, up


def load_urdf(path, base_link: str | None = None, tip_link: str | None = None, *,
              T_flange_tool=None, name: str | None = None) -> SerialChain:
    """Load the base→tip chain of a URDF robot description.

    Parameters
    ----------
    path : str or Path
        URDF file (plain XML; run xacro first).
    base_link : str, optional
        The chain's base frame; the tree's root link by default.
    tip_link : str, optional
        The chain's tip (flange) frame; by default the arm's tip (module docstring: the last
        link the arm's end effectors hang from, fingers, mimic joints and fixed sensor frames
        left out; an error naming the candidates when two arms tie).
    T_flange_tool : array_like, shape (4, 4), optional
        Tool (TCP) in the tip frame, mm; identity by default.
    name : str, optional
        Chain name for messages; the URDF robot name by default.

    Returns
    -------
    SerialChain
        Revolute and continuous joints in rad, prismatic joints in mm; joint names and limits
        from the file (continuous joints and ±inf limits unbounded); lengths in mm. Its
        ``repr`` is ``name: base → tip, n joints (names)``; ``notes`` says how a default tip
        was chosen and which limits were read as unbounded.

    Raises
    ------
    ConfigError
        A missing, oversized or malformed file; an unknown base or tip link (the message lists
        the links); a tip that is not below the base; an ambiguous default tip (the candidates
        are named); a zero joint axis; non-finite numbers or an origin beyond
        :data:`MAX_ORIGIN_M`; xacro; mimic, floating or planar joints on the path, closed loops
        (unsupported).

    Examples
    --------
    >>> from posekit.robots import bundled_robot_path
    >>> arm = load_urdf(bundled_robot_path("ur10"))
    >>> arm.n_joints, arm.base_link, arm.tip_link
    (6, 'base_link', 'ee_link')
    """
    path = Path(path)
    robot = _parse(path, _read_xml(path)).robot
    tree = JointTree(path, [link.name for link in robot.links], robot.joints)
    links = tree.links
    for role, link in (("base_link", base_link), ("tip_link", tip_link)):
        if link is not None and link not in tree.children:
            raise ConfigError(f"{path}: unknown {role} '{link}'; the file's links are {_names(links)}")
    base = base_link if base_link is not None else tree.root()
    notes = []
    if tip_link is None:
        found = tree.default_tip(base)
        tip = found.tip
        left_out = f"; left out: {', '.join(found.excluded)}" if found.excluded else ""
        notes.append(("default tip: the gripper's link" if found.how == "hand" else "default tip: the arm's end")
                     + left_out)
    else:
        tip = tip_link
    if tip == base:
        raise ConfigError(f"{path}: tip_link '{tip}' is the base_link; expected a link below it")
    joints = tree.path_joints(base, tip)

    origins, axes, types, names, lo, hi = [], [], [], [], [], []
    pending = np.eye(4)
    for j in joints:
        if j.type == "fixed":
            pending = pending @ _origin(path, j)
            continue
        if j.type not in _MOVING:
            raise ConfigError(f"{path}: joint '{j.name}': unsupported type '{j.type}' on the chain; "
                              "expected revolute, continuous, prismatic or fixed")
        if j.mimic is not None:
            raise ConfigError(f"{path}: joint '{j.name}': unsupported: mimic joint on the chain "
                              f"(mimics '{j.mimic.joint}'); expected independent joints")
        origins.append(pending @ _origin(path, j))
        pending = np.eye(4)
        axes.append(_axis(path, j))
        kind = _MOVING[j.type]
        types.append(kind)
        names.append(j.name)
        low, up = _limits(path, j, _M_TO_MM if kind == PRISMATIC else 1.0, notes)
        lo.append(low)
        hi.append(up)
    if not origins:
        raise ConfigError(f"{path}: no moving joint between base_link '{base}' and tip_link '{tip}'")
    return SerialChain(
        origins=np.array(origins), axes=np.array(axes), joint_types=tuple(types),
        T_last_flange=pending, q_min=np.array(lo), q_max=np.array(hi),
        T_flange_tool=T_flange_tool, name=name or robot.name or path.stem,
        joint_names=tuple(names), base_link=base, tip_link=tip, notes=tuple(notes),
    )
