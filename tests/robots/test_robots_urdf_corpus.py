"""Real URDF files (tests/data/urdf, sources and licences in its README): every file loads, every
chain agrees with Pinocchio, and the default chain of each arm is its arm."""

from pathlib import Path

import numpy as np
import pytest

from posekit.errors import ConfigError
from posekit.robots import load_urdf
from tests.robots.pinocchio_reference import max_differences, random_q

CORPUS = Path(__file__).resolve().parents[1] / "data" / "urdf"

#: file -> (base, tip, number of joints) of the default chain. Why, where not obvious:
#: Panda/Jaco/WidowX — the tip is the link the gripper's fingers hang from; FR3 — its last arm link
#: carries the flange link8 and a self-collision frame, so the last link both hang from is link7;
#: Z1 — the single jaw joint (``jointGripper``) is the gripper's; Gen3 — end_effector_link carries
#: the camera frames and tool_frame; MH5/SIA10D — files without a tool0 frame.
ARMS = {
    "franka_panda.urdf": ("panda_link0", "panda_hand", 7),
    "franka_fr3.urdf": ("fr3_link0", "fr3_link7", 7),
    "ur5e.urdf": ("base_link", "tool0", 6),
    "kuka_iiwa14_r820.urdf": ("base_link", "tool0", 7),
    "kuka_kr210l150.urdf": ("base_link", "tool0", 6),
    "fanuc_crx10ial.urdf": ("base_link", "tool0", 6),
    "fanuc_lrmate200id.urdf": ("base_link", "tool0", 6),
    "fanuc_m10ia.urdf": ("base_link", "tool0", 6),
    "yaskawa_mh5.urdf": ("base_link", "link_t", 6),
    "yaskawa_sia10d.urdf": ("world", "link_t", 7),
    "yaskawa_sia5d.urdf": ("base_link", "tool0", 7),
    "abb_crb15000_5_95.urdf": ("base_link", "tool0", 6),
    "abb_irb2400.urdf": ("base_link", "tool0", 6),
    "staubli_rx160.urdf": ("base_link", "tool0", 6),
    "staubli_tx2_60.urdf": ("base_link", "tool0", 6),
    "kinova_gen3.urdf": ("base_link", "end_effector_link", 7),
    "kinova_j2n6s300.urdf": ("world", "j2n6s300_link_6", 6),
    "unitree_z1.urdf": ("world", "gripperStator", 6),
    "interbotix_wx250s.urdf": ("/base_link", "/ee_arm_link", 6),
    "schunk_lwa4p.urdf": ("world", "arm_6_link", 6),
}
#: Files with two equal arms: no default, the message names both candidate tips, which load.
TWO_ARMS = {
    "abb_yumi.urdf": ("yumi_body", ("gripper_r_base", "gripper_l_base")),
    "franka_dual_panda.urdf": ("base", ("panda_1_hand", "panda_2_hand")),
    "pr2.urdf": ("torso_lift_link", ("r_gripper_palm_link", "l_gripper_palm_link")),
}
#: Explicit chains of the files without a default arm: (file, base, tip).
EXPLICIT = [
    ("robotiq_2f_85.urdf", None, "left_outer_finger"),       # the driven finger joint alone
    ("abb_irb5400.urdf", "base_link", "link_4"),             # up to the wrist's mimic joint
    ("pr2.urdf", "base_footprint", "head_tilt_link"),        # a side branch of a tree
]
#: Pinocchio agreement: position mm, rotation entries, Jacobian mm/rad and rad/rad (measured worst
#: over the corpus: 9e-12 mm, 2e-13, 2e-14 relative).
TOL = (1e-8, 1e-11, 1e-8, 1e-11)


def _chains():
    out = [(f, load_urdf(CORPUS / f)) for f in ARMS]
    out += [(f, load_urdf(CORPUS / f, tip_link=tip)) for f, (_, tips) in TWO_ARMS.items() for tip in tips]
    out += [(f, load_urdf(CORPUS / f, base, tip)) for f, base, tip in EXPLICIT]
    return out


def test_corpus_is_the_documented_one():
    files = sorted(p.name for p in CORPUS.glob("*.urdf"))
    assert files == sorted({*ARMS, *TWO_ARMS, *(f for f, _, _ in EXPLICIT)})
    assert len(files) >= 20
    readme = (CORPUS / "README.md").read_text()
    assert all(f"`{f}`" in readme for f in files)


@pytest.mark.parametrize("name", sorted(ARMS))
def test_default_chain_is_the_arm(name):
    base, tip, n = ARMS[name]
    chain = load_urdf(CORPUS / name)
    assert (chain.base_link, chain.tip_link, chain.n_joints) == (base, tip, n)
    assert not any("finger" in j.lower() or "gripper" in j.lower() for j in chain.joint_names)
    assert chain.summary.startswith(f"{chain.name}: {base} → {tip}, {n} joints (")
    assert chain.notes and chain.notes[0].startswith("default tip: ")


@pytest.mark.parametrize("name", sorted(TWO_ARMS))
def test_two_equal_arms_name_both_tips(name):
    at, tips = TWO_ARMS[name]
    with pytest.raises(ConfigError, match=rf"the default tip is ambiguous: the tree branches at '{at}' into "
                                          rf"2 chains of \d+ moving joints; candidate tips '{tips[0]}', '{tips[1]}'; "
                                          r"pass tip_link \(--tip-link\)") as info:
        load_urdf(CORPUS / name)
    assert "\n" not in str(info.value)


def test_every_chain_agrees_with_pinocchio():
    rng = np.random.default_rng(11)
    chains = _chains()
    assert len(chains) >= 28
    for name, chain in chains:
        worst = max_differences(CORPUS / name, chain, random_q(chain, rng, 8))
        assert np.all(worst <= TOL), (name, chain.summary, worst)


def test_refused_kinds_in_real_files():
    """What stays refused: a gripper alone has no arm, a mimic joint on the chain."""
    with pytest.raises(ConfigError, match=r"robotiq_2f_85\.urdf: no arm joint below base_link 'robotiq_arg2f_base_link' "
                                          r"\(mimic and gripper joints do not count\)"):
        load_urdf(CORPUS / "robotiq_2f_85.urdf")
    with pytest.raises(ConfigError, match=r"joint 'left_inner_finger_joint': unsupported: mimic joint on the chain "
                                          r"\(mimics 'finger_joint'\)"):
        load_urdf(CORPUS / "robotiq_2f_85.urdf", tip_link="left_inner_finger")
    with pytest.raises(ConfigError, match=r"abb_irb5400\.urdf: joint 'joint5b': unsupported: mimic joint on the chain "
                                          r"\(mimics 'joint5'\)"):
        load_urdf(CORPUS / "abb_irb5400.urdf")


def test_panda_default_leaves_out_the_fingers():
    chain = load_urdf(CORPUS / "franka_panda.urdf")
    assert chain.joint_names == tuple(f"panda_joint{i}" for i in range(1, 8))
    assert chain.notes[0] == "default tip: the gripper's link; left out: panda_finger_joint1, panda_finger_joint2"
    z1 = load_urdf(CORPUS / "unitree_z1.urdf")
    assert z1.notes[0] == "default tip: the arm's end; left out: jointGripper"
