"""The joint tree of a URDF file and the default chain through it (the arm, not a finger).

A URDF describes a tree of links joined by joints. A user who names no tip wants the arm: the
chain from the root down to the link that carries the arm's end effectors. This module finds it
in one pass over the tree (linear in the number of links, so a 16 MB file of 45,000 links takes
well under a second):

1. **weights** — for every link, the largest number of *independent* moving joints on a path
   from it down to a leaf: revolute, continuous and prismatic joints that mimic no other joint
   and are not a gripper's (a joint named like :data:`GRIPPER_WORDS`: a single gripper jaw, as
   on a Unitree Z1, looks like one more arm joint otherwise; link names are not used — an
   Interbotix arm calls its wrist link ``gripper_link``);
2. **the walk** — from the base, follow the branch with the largest weight. Branches without an
   independent moving joint (sensor frames, ``tool0``, a parallel-link cylinder that mimics an
   arm joint) are side branches and are passed by. The walk stops at

   * a **hand**: a link below at least one arm joint where two or more branches move (counting
     mimic joints), each with fewer independent joints than the arm above it — gripper fingers
     (Panda's two slides, one mimicking the other; a Robotiq 2F-85's mimic linkage; a Kinova
     three-finger hand; TIAGo's five-finger hand of 7-joint fingers below an 8-joint arm);
   * the **end of the arm**: no arm joint below; the walk follows a fixed joint towards the one
     branch where a gripper moves, or else a single fixed joint (``flange`` → ``tool0``), and
     stops where fixed frames branch (the last link that every end-effector frame hangs from)
     or at a single gripper joint (a Z1's jaw);
   * a **tie**: two branches of equal, largest weight (the arms of a dual-arm robot or a
     humanoid) — no default; the tips each branch would give are the candidates.

The tree's checks (every joint's links defined, no link with two parents, one root) are made
here too; each failure is a one-line :class:`~posekit.errors.ConfigError`.
"""

import re
from dataclasses import dataclass

from posekit.errors import ConfigError

__all__ = ["GRIPPER_WORDS", "DefaultTip", "JointTree"]

#: Words in a joint's name that make a moving joint a gripper's (case-insensitive).
GRIPPER_WORDS = ("finger", "gripper", "jaw", "thumb", "knuckle")
_GRIPPER = re.compile("|".join(GRIPPER_WORDS), re.IGNORECASE)

#: Link names listed in one message, at most.
_MAX_LISTED = 10

_MOVING = ("revolute", "continuous", "prismatic")


def _names(names, quote: bool = False, limit: int = 120) -> str:
    """Names joined by ', ' up to about ``limit`` characters, then 'and N more'."""
    names = list(names)
    out, used = [], 0
    for k, n in enumerate(names):
        item = f"'{n}'" if quote else str(n)
        if out and used + len(item) > limit:
            return ", ".join(out) + f" and {len(names) - k} more"
        out.append(item)
        used += len(item) + 2
    return ", ".join(out)


def _independent(j) -> bool:
    """A moving joint that mimics no other joint and is not a gripper's (by its name)."""
    return j.type in _MOVING and j.mimic is None and not _GRIPPER.search(j.name)


@dataclass(frozen=True)
class DefaultTip:
    """The default tip of a tree and how it was found.

    Attributes
    ----------
    tip : str
        The tip link.
    how : str
        ``"hand"`` (the link the gripper's fingers hang from) or ``"end"`` (the arm's last link,
        after fixed end-effector frames).
    excluded : tuple of str
        Moving joints below the tip that the default chain leaves out (fingers), at most
        ``_MAX_LISTED``.
    """

    tip: str
    how: str
    excluded: tuple[str, ...] = ()


class JointTree:
    """Links and joints of a URDF model as a tree.

    Parameters
    ----------
    path : Path
        The file, for messages.
    links : sequence of str
        Every link name, in file order.
    joints : sequence
        yourdfpy joints (``name``, ``type``, ``parent``, ``child``, ``mimic``).

    Raises
    ------
    ConfigError
        A joint naming an undefined link, a link that is the child of two joints (a closed
        loop).
    """

    def __init__(self, path, links, joints):
        self.path = path
        self.links = list(links)
        names = set(self.links)
        self.parent_of = {}
        self.children = {link: [] for link in self.links}
        for j in joints:
            for role, link in (("parent", j.parent), ("child", j.child)):
                if link not in names:
                    raise ConfigError(f"{path}: joint '{j.name}': {role} link '{link}' is not defined; "
                                      f"expected one of {_names(sorted(names))}")
            if j.child in self.parent_of:
                raise ConfigError(f"{path}: unsupported URDF: closed loop (link '{j.child}' is the child of "
                                  f"joints '{self.parent_of[j.child].name}' and '{j.name}'); expected a tree")
            self.parent_of[j.child] = j
            self.children[j.parent].append(j)

    def root(self) -> str:
        """The one link without a parent joint, or a ConfigError."""
        roots = [link for link in self.links if link not in self.parent_of]
        if len(roots) != 1:
            raise ConfigError(f"{self.path}: unsupported URDF: {len(roots)} root links {roots[:_MAX_LISTED]} "
                              "(a closed loop or a disconnected link); expected a tree with one root")
        return roots[0]

    def path_joints(self, base: str, tip: str) -> list:
        """Joints from ``base`` down to ``tip``, in order, or a ConfigError."""
        chain = []
        link = tip
        seen = set()
        while link != base:
            if link in seen:
                raise ConfigError(f"{self.path}: unsupported URDF: closed loop through link '{link}'")
            seen.add(link)
            j = self.parent_of.get(link)
            if j is None:
                raise ConfigError(f"{self.path}: tip_link '{tip}' is not below base_link '{base}'; "
                                  "expected a tip link on a path down from the base")
            chain.append(j)
            link = j.parent
        return chain[::-1]

    def _subtree(self, base: str) -> list[str]:
        """Links below ``base`` (itself first), parents before children."""
        order, k = [base], 0
        while k < len(order):
            order.extend(j.child for j in self.children[order[k]])
            k += 1
        return order

    def default_tip(self, base: str) -> DefaultTip:
        """The arm's tip below ``base`` (see the module docstring), or a ConfigError.

        Raises
        ------
        ConfigError
            No independent moving joint below ``base``; or a tie between branches (the message
            names the link where the tree branches and the candidate tips).
        """
        order = self._subtree(base)
        weight, moves = {}, {}
        for link in reversed(order):                    # children before parents
            kids = self.children[link]
            weight[link] = max((_independent(j) + weight[j.child] for j in kids), default=0)
            moves[link] = any(j.type != "fixed" or moves[j.child] for j in kids)
        if weight[base] == 0:
            raise ConfigError(f"{self.path}: no arm joint below base_link '{base}' (mimic and gripper joints do not "
                              "count); expected a serial arm, or pass tip_link (--tip-link)")
        found, ties = [], []
        stack = [(base, 0)]
        while stack:
            link, arm = stack.pop()
            tip, tie = self._walk(link, arm, weight, moves)
            if tie is None:
                found.append(tip)
            else:
                ties.append(tie)
                stack.extend(reversed(tie[2]))
        if ties:
            at, top, branches = ties[0]
            raise ConfigError(f"{self.path}: the default tip is ambiguous: the tree branches at '{at}' into "
                              f"{len(branches)} chains of {top} moving joints; candidate tips "
                              f"{_names((t.tip for t in found), quote=True)}; pass tip_link (--tip-link)")
        return found[0]

    def _walk(self, link: str, arm: int, weight: dict, moves: dict):
        """Walk down from ``link`` with ``arm`` independent joints above it.

        Returns ``(DefaultTip, None)``, or ``(None, (link, weight, [(child, arm), ...]))`` at a tie.
        """
        while True:
            kids = self.children[link]
            w = {j.name: _independent(j) + weight[j.child] for j in kids}
            moving = [j for j in kids if j.type != "fixed" or moves[j.child]]
            heavy = [j for j in kids if w[j.name] > 0]
            if arm >= 1 and len(moving) >= 2 and all(w[j.name] < arm for j in moving):
                fingers = [j.name for j in self._moving_below(link)]
                return DefaultTip(link, "hand", tuple(fingers[:_MAX_LISTED])), None
            if heavy:
                top = max(w[j.name] for j in heavy)
                best = [j for j in heavy if w[j.name] == top]
                if len(best) > 1:
                    return None, (link, top, [(j.child, arm + _independent(j)) for j in best])
                j = best[0]
                link, arm = j.child, arm + _independent(j)
                continue
            ahead = moving if moving else kids          # towards the gripper, else the one fixed frame
            if len(ahead) == 1 and ahead[0].type == "fixed":
                link = ahead[0].child
                continue
            excluded = [j.name for j in self._moving_below(link)]
            return DefaultTip(link, "end", tuple(excluded[:_MAX_LISTED])), None

    def _moving_below(self, link: str) -> list:
        """Moving joints below ``link``, breadth first."""
        out, todo, k = [], [link], 0
        while k < len(todo):
            for j in self.children[todo[k]]:
                if j.type != "fixed":
                    out.append(j)
                todo.append(j.child)
            k += 1
        return out
