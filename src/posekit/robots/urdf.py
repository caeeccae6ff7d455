"""A user's own robot from a URDF file: the base→tip path as a :class:`SerialChain`.

The file is read with yourdfpy (a maintained URDF parser) after a well-formedness check of
its XML; posekit then takes the unique path of joints from ``base_link`` down to
``tip_link``, folds fixed joints into the next joint's origin (or into the flange after the
last moving joint), and keeps every moving joint's axis, limits and name. Joints off that
path (grippers, cameras, the passive cylinders of a parallel-link arm) are ignored. URDF
lengths are metres and are converted to mm; a prismatic joint's variable is then in mm.

Unsupported (a one-line error that says so): mimic joints and floating or planar joints on the
path, closed loops (a link with two parent joints), and DTD entities.
"""

import io
import math
from pathlib import Path

import numpy as np

from posekit.errors import ConfigError
from posekit.io import quote

from .chain import PRISMATIC, REVOLUTE, SerialChain

__all__ = ["MAX_URDF_BYTES", "load_urdf"]

#: Largest URDF file read (bytes); real descriptions are 10 kB – 1 MB.
MAX_URDF_BYTES = 16 * 1024 * 1024

_MOVING = {"revolute": REVOLUTE, "continuous": REVOLUTE, "prismatic": PRISMATIC}
_M_TO_MM = 1000.0


def _read_xml(path: Path) -> bytes:
    """The file's bytes after the checks every reader makes: exists, size, well-formed XML."""
    from posekit.io import read_bytes

    if not path.exists():
        raise ConfigError(f"{path}: no such URDF file")
    data = read_bytes(path, expected="a URDF file", error=ConfigError, limit=MAX_URDF_BYTES)
    if b"<!ENTITY" in data:
        raise ConfigError(f"{path}: unsupported URDF: DTD entities; expected plain XML (expand xacro first)")
    from posekit._extras import require

    etree = require("lxml.etree", "urdf", f"reading the URDF file {path.name}")
    parser = etree.XMLParser(resolve_entities=False, no_network=True, huge_tree=False)
    try:
        root = etree.fromstring(data, parser)
    except etree.XMLSyntaxError as exc:
        msg = " ".join(str(exc).split())
        raise ConfigError(f"{path}: malformed XML: {msg[:160]}; expected a URDF file") from None
    if root.tag != "robot":
        raise ConfigError(f"{path}: root element <{str(root.tag)[:40]}>; expected a URDF <robot> element")
    for i, el in enumerate(root.iter("link", "joint")):
        if not el.get("name"):
            raise ConfigError(f"{path}: <{el.tag}> number {i + 1} has no name attribute; expected name=\"...\"")
    if any(el.prefix == "xacro" or "xacro" in str(el.tag).split("}")[0] for el in root.iter()) or b"${" in data:
        raise ConfigError(f"{path}: a xacro file; expected plain URDF (run xacro first)")
    for el in root.iter("origin", "axis", "limit", "mimic"):       # numbers by value: not '١٢' or '1_0'
        for key, value in el.attrib.items():
            if key != "joint" and (not value.isascii() or "_" in value):
                raise ConfigError(f"{path}: <{el.tag}> {key}={quote(value, 40)}: expected plain decimal numbers")
    return data


def _parse(path: Path, data: bytes):
    """The yourdfpy model of a well-formed file, or a ConfigError naming the element."""
    import contextlib

    from posekit._extras import require

    yourdfpy = require("yourdfpy", "urdf", f"reading the URDF file {path.name}")

    try:
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
            return yourdfpy.URDF.load(
                io.BytesIO(data), load_meshes=False, build_scene_graph=False,
                build_collision_scene_graph=False, load_collision_meshes=False,
            )
    except (ValueError, TypeError, KeyError, AttributeError, IndexError) as exc:
        raise ConfigError(f"{path}: malformed URDF ({type(exc).__name__}: {str(exc)[:120]}); "
                          "expected <joint> elements with parent, child, origin xyz/rpy of 3 numbers") from None


def _tree(path: Path, robot):
    """``(joints_by_child, links)``: each link's parent joint, and every link name."""
    links = [link.name for link in robot.links]
    names = set(links)
    parent_of = {}
    for j in robot.joints:
        for role, link in (("parent", j.parent), ("child", j.child)):
            if link not in names:
                raise ConfigError(f"{path}: joint '{j.name}': {role} link '{link}' is not defined; "
                                  f"expected one of {sorted(names)[:20]}")
        if j.child in parent_of:
            raise ConfigError(f"{path}: unsupported URDF: closed loop (link '{j.child}' is the child of "
                              f"joints '{parent_of[j.child].name}' and '{j.name}'); expected a tree")
        parent_of[j.child] = j
    return parent_of, links


def _root(path: Path, parent_of: dict, links: list) -> str:
    roots = [link for link in links if link not in parent_of]
    if len(roots) != 1:
        raise ConfigError(f"{path}: unsupported URDF: {len(roots)} root links {roots[:10]} "
                          "(a closed loop or a disconnected link); expected a tree with one root")
    return roots[0]


def _path_joints(path: Path, parent_of: dict, base: str, tip: str) -> list:
    """Joints from ``base`` down to ``tip`` in order, or a ConfigError."""
    chain = []
    link = tip
    seen = set()
    while link != base:
        if link in seen:
            raise ConfigError(f"{path}: unsupported URDF: closed loop through link '{link}'")
        seen.add(link)
        j = parent_of.get(link)
        if j is None:
            raise ConfigError(f"{path}: tip_link '{tip}' is not below base_link '{base}'; "
                              "expected a tip link on a path down from the base")
        chain.append(j)
        link = j.parent
    return chain[::-1]


def _default_tip(path: Path, parent_of: dict, links: list, base: str) -> str:
    """The leaf below ``base`` with the most moving joints on its path (unique), else an error."""
    children = {j.parent for j in parent_of.values()}
    best, best_n, tied = None, -1, []
    for leaf in (link for link in links if link not in children):
        try:
            joints = _path_joints(path, parent_of, base, leaf)
        except ConfigError:
            continue
        n = sum(j.type in _MOVING and j.mimic is None for j in joints)
        if n > best_n:
            best, best_n, tied = leaf, n, [leaf]
        elif n == best_n:
            tied.append(leaf)
    if best is None or best_n == 0:
        raise ConfigError(f"{path}: no moving joint below base_link '{base}'; expected a serial arm")
    if len(tied) > 1:
        raise ConfigError(f"{path}: tip_link is ambiguous: {tied[:10]} each end a path of {best_n} "
                          "moving joints; pass tip_link")
    return best


def _origin(path: Path, j) -> np.ndarray:
    T = np.eye(4) if j.origin is None else np.array(j.origin, dtype=np.float64)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise ConfigError(f"{path}: joint '{j.name}': origin xyz/rpy must be 3 finite numbers each")
    T = T.copy()
    T[:3, 3] *= _M_TO_MM
    return T


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
        The chain's tip (flange) frame; by default the leaf below ``base_link`` whose path has
        the most moving joints (an error if two tie).
    T_flange_tool : array_like, shape (4, 4), optional
        Tool (TCP) in the tip frame, mm; identity by default.
    name : str, optional
        Chain name for messages; the URDF robot name by default.

    Returns
    -------
    SerialChain
        Revolute and continuous joints in rad, prismatic joints in mm; joint names and limits
        from the file (continuous joints unlimited); lengths in mm.

    Raises
    ------
    ConfigError
        A missing, oversized or malformed file; an unknown base or tip link (the message lists
        the links); a tip that is not below the base; a zero joint axis; non-finite numbers;
        mimic, floating or planar joints on the path, closed loops (unsupported).

    Examples
    --------
    >>> from posekit.robots import bundled_robot_path
    >>> arm = load_urdf(bundled_robot_path("ur10"))
    >>> arm.n_joints, arm.base_link, arm.tip_link
    (6, 'base_link', 'ee_link')
    """
    path = Path(path)
    data = _read_xml(path)
    robot = _parse(path, data).robot
    parent_of, links = _tree(path, robot)
    for role, link in (("base_link", base_link), ("tip_link", tip_link)):
        if link is not None and link not in links:
            raise ConfigError(f"{path}: unknown {role} '{link}'; the file's links are {', '.join(links[:40])}")
    base = base_link if base_link is not None else _root(path, parent_of, links)
    tip = tip_link if tip_link is not None else _default_tip(path, parent_of, links, base)
    if tip == base:
        raise ConfigError(f"{path}: tip_link '{tip}' is the base_link; expected a link below it")
    joints = _path_joints(path, parent_of, base, tip)

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
        axis = np.array([1.0, 0.0, 0.0] if j.axis is None else j.axis, dtype=np.float64)
        if axis.shape != (3,) or not np.all(np.isfinite(axis)) or np.linalg.norm(axis) < 1e-12:
            raise ConfigError(f"{path}: joint '{j.name}': axis {axis.tolist()}; expected a non-zero direction")
        origins.append(pending @ _origin(path, j))
        pending = np.eye(4)
        axes.append(axis / np.linalg.norm(axis))
        kind = _MOVING[j.type]
        types.append(kind)
        names.append(j.name)
        scale = _M_TO_MM if kind == PRISMATIC else 1.0
        limit = j.limit
        low = -math.inf if j.type == "continuous" or limit is None or limit.lower is None else limit.lower * scale
        up = math.inf if j.type == "continuous" or limit is None or limit.upper is None else limit.upper * scale
        if not (low <= up):
            raise ConfigError(f"{path}: joint '{j.name}': limit lower {low} > upper {up}; expected lower <= upper")
        lo.append(low)
        hi.append(up)
    if not origins:
        raise ConfigError(f"{path}: no moving joint between base_link '{base}' and tip_link '{tip}'")
    return SerialChain(
        origins=np.array(origins), axes=np.array(axes), joint_types=tuple(types),
        T_last_flange=pending, q_min=np.array(lo), q_max=np.array(hi),
        T_flange_tool=T_flange_tool, name=name or robot.name or path.stem,
        joint_names=tuple(names), base_link=base, tip_link=tip,
    )
