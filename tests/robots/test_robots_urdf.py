"""URDF chains: load_urdf against Pinocchio and an independent composition, bad input."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from posekit.errors import ConfigError
from posekit.robots import (
    PRISMATIC,
    REVOLUTE,
    SerialChain,
    bundled_robot_path,
    load_urdf,
    puma560,
    robot_model,
)
from tests.robots.pinocchio_reference import PinocchioChain, random_q

pin = pytest.importorskip("pinocchio")

#: A synthetic arm written for these tests (not by posekit): skewed joint axes, an rpy-rotated
#: origin on every joint, fixed joints before, between and after the moving ones, a prismatic
#: joint, a continuous joint, and a side branch (a camera and a gripper finger) off the path.
SKEWED_URDF = """<?xml version="1.0"?>
<robot name="skewed">
  <link name="world"/><link name="pedestal"/><link name="l1"/><link name="l2"/><link name="l2b"/>
  <link name="l3"/><link name="l4"/><link name="l5"/><link name="flange"/><link name="tcp"/>
  <link name="camera"/><link name="finger"/>
  <joint name="mount" type="fixed"><parent link="world"/><child link="pedestal"/>
    <origin xyz="0.10 -0.05 0.40" rpy="0.02 -0.03 0.5"/></joint>
  <joint name="j1" type="revolute"><parent link="pedestal"/><child link="l1"/>
    <origin xyz="0 0 0.25" rpy="0 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/>
    <origin xyz="0.05 0.02 0.30" rpy="0.3 -0.2 0.1"/><axis xyz="0.2 1 0.1"/>
    <limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <joint name="spacer" type="fixed"><parent link="l2"/><child link="l2b"/>
    <origin xyz="0.40 0 0.01" rpy="0 0.1 0"/></joint>
  <joint name="slide" type="prismatic"><parent link="l2b"/><child link="l3"/>
    <origin xyz="0.02 0 0" rpy="0 0 0.2"/><axis xyz="1 0.3 -0.2"/>
    <limit lower="-0.05" upper="0.20" effort="1" velocity="1"/></joint>
  <joint name="j4" type="continuous"><parent link="l3"/><child link="l4"/>
    <origin xyz="0.10 0 0" rpy="-0.4 0 0.3"/><axis xyz="-0.5 0.5 0.7"/></joint>
  <joint name="j5" type="revolute"><parent link="l4"/><child link="l5"/>
    <origin xyz="0 0.05 0.12" rpy="1.2 0.1 -0.7"/><axis xyz="0 -1 0"/>
    <limit lower="-2.5" upper="2.5" effort="1" velocity="1"/></joint>
  <joint name="j6" type="revolute"><parent link="l5"/><child link="flange"/>
    <origin xyz="0.08 0 0" rpy="0 1.5707963 0"/><axis xyz="1 1 1"/>
    <limit lower="-6" upper="6" effort="1" velocity="1"/></joint>
  <joint name="tool" type="fixed"><parent link="flange"/><child link="tcp"/>
    <origin xyz="0 0 0.15" rpy="0.1 0.2 0.3"/></joint>
  <joint name="cam" type="fixed"><parent link="l2"/><child link="camera"/>
    <origin xyz="0.1 0.1 0.1" rpy="0 0 0"/></joint>
  <joint name="grip" type="prismatic"><parent link="l5"/><child link="finger"/>
    <origin xyz="0 0 0.05" rpy="0 0 0"/><axis xyz="0 1 0"/>
    <limit lower="0" upper="0.04" effort="1" velocity="1"/></joint>
</robot>
"""

#: Joints of SKEWED_URDF's world -> tcp path: (name, xyz m, rpy rad, axis, kind); None = fixed.
SKEWED_PATH = [
    ("mount", (0.10, -0.05, 0.40), (0.02, -0.03, 0.5), None, None),
    ("j1", (0, 0, 0.25), (0, 0, 0), (0, 0, 1), REVOLUTE),
    ("j2", (0.05, 0.02, 0.30), (0.3, -0.2, 0.1), (0.2, 1, 0.1), REVOLUTE),
    ("spacer", (0.40, 0, 0.01), (0, 0.1, 0), None, None),
    ("slide", (0.02, 0, 0), (0, 0, 0.2), (1, 0.3, -0.2), PRISMATIC),
    ("j4", (0.10, 0, 0), (-0.4, 0, 0.3), (-0.5, 0.5, 0.7), REVOLUTE),
    ("j5", (0, 0.05, 0.12), (1.2, 0.1, -0.7), (0, -1, 0), REVOLUTE),
    ("j6", (0.08, 0, 0), (0, 1.5707963, 0), (1, 1, 1), REVOLUTE),
    ("tool", (0, 0, 0.15), (0.1, 0.2, 0.3), None, None),
]


@pytest.fixture(scope="module")
def skewed_path(tmp_path_factory):
    path = tmp_path_factory.mktemp("urdf") / "skewed.urdf"
    path.write_text(SKEWED_URDF)
    return path


def reference_fk(q) -> np.ndarray:
    """Independent composition of SKEWED_PATH: URDF rpy (fixed-axis x, y, z) via scipy, the joint
    motion by scipy's axis-angle, m -> mm. q (6,), rad / mm for the slide."""
    T = np.eye(4)
    k = 0
    for _, xyz, rpy, axis, kind in SKEWED_PATH:
        origin = np.eye(4)
        origin[:3, :3] = Rotation.from_euler("xyz", rpy).as_matrix()
        origin[:3, 3] = 1000.0 * np.asarray(xyz)
        T = T @ origin
        if kind is not None:
            a = np.asarray(axis, float) / np.linalg.norm(axis)
            motion = np.eye(4)
            if kind == REVOLUTE:
                motion[:3, :3] = Rotation.from_rotvec(a * q[k]).as_matrix()
            else:
                motion[:3, 3] = a * q[k]
            T = T @ motion
            k += 1
    return T


def _random_q(chain, rng, n):
    return random_q(chain, rng, n)


def test_skewed_chain_structure(skewed_path):
    chain = load_urdf(skewed_path, "world", "tcp")
    assert chain.joint_names == ("j1", "j2", "slide", "j4", "j5", "j6")
    assert chain.joint_types == (REVOLUTE, REVOLUTE, PRISMATIC, REVOLUTE, REVOLUTE, REVOLUTE)
    np.testing.assert_allclose(chain.q_min, [-3, -2, -50, -np.inf, -2.5, -6])
    np.testing.assert_allclose(chain.q_max, [3, 2, 200, np.inf, 2.5, 6])
    assert (chain.base_link, chain.tip_link) == ("world", "tcp")
    # the default base is the root. Its default tip: at l5 two branches move, j6 (-> flange -> tcp)
    # and the slide 'grip' (-> finger), each with one joint, fewer than the five arm joints above:
    # a hand, by the rule (what a gripper whose fingers hang before the last joint gives)
    chain = load_urdf(skewed_path)
    assert (chain.base_link, chain.tip_link, chain.joint_names) == ("world", "l5", ("j1", "j2", "slide", "j4", "j5"))
    assert chain.notes == ("default tip: the gripper's link; left out: j6, grip",)
    assert repr(chain) == "<SerialChain skewed: world → l5, 5 joints (j1, j2, slide, j4, j5)>"
    assert load_urdf(skewed_path, tip_link="tcp").base_link == "world"


def test_default_tip_follows_the_arm_past_a_named_finger(tmp_path):
    """A finger named as one, on the flange, has no arm joint: the walk goes on to the flange and
    stops there (the finger moves, and the tcp and a camera hang from it)."""
    text = SKEWED_URDF.replace('name="grip" type="prismatic"><parent link="l5"/>',
                               'name="finger_joint" type="prismatic"><parent link="flange"/>').replace(
        "</robot>", '<link name="flange_cam"/><joint name="fcam" type="fixed"><parent link="flange"/>'
                    '<child link="flange_cam"/></joint></robot>')
    chain = load_urdf(_write(tmp_path, text, "named.urdf"))
    assert (chain.tip_link, chain.n_joints) == ("flange", 6)
    assert chain.notes == ("default tip: the arm's end; left out: finger_joint",)


@pytest.mark.parametrize("name", ["skewed", "ur10", "abb_irb6640"])
def test_fk_and_jacobian_match_pinocchio(name, skewed_path):
    if name == "skewed":
        path, chain = skewed_path, load_urdf(skewed_path, "world", "tcp")
    else:
        path, chain = bundled_robot_path(name), robot_model(name)
    ref = PinocchioChain(path, chain)
    qs = _random_q(chain, np.random.default_rng(3), 40)
    Ts, Js = chain.forward_kinematics_and_jacobian(qs)
    for q, T, J in zip(qs, Ts, Js):
        T_pin, J_pin = ref(q)
        np.testing.assert_allclose(T[:3, 3], T_pin[:3, 3], atol=1e-6, rtol=0)  # mm
        np.testing.assert_allclose(T[:3, :3], T_pin[:3, :3], atol=1e-9, rtol=0)
        np.testing.assert_allclose(J[:3], J_pin[:3], atol=1e-6, rtol=0)  # mm/rad
        np.testing.assert_allclose(J[3:], J_pin[3:], atol=1e-9, rtol=0)


def test_skewed_fk_matches_independent_composition(skewed_path):
    chain = load_urdf(skewed_path, "world", "tcp")
    for q in _random_q(chain, np.random.default_rng(4), 30):
        np.testing.assert_allclose(chain.forward_kinematics(q), reference_fk(q), atol=1e-9, rtol=0)


@pytest.mark.parametrize("make", [lambda p: load_urdf(p, "world", "tcp"), lambda p: robot_model("abb_irb6640"),
                                  lambda p: puma560()])
def test_jacobian_matches_finite_differences(make, skewed_path):
    """Column i = d(position)/dq_i and the rotation-vector rate of R(q + h e_i) R(q)^T."""
    chain = make(skewed_path)
    h = 1e-6
    for q in _random_q(chain, np.random.default_rng(5), 10):
        T = chain.forward_kinematics(q)
        J = chain.geometric_jacobian(q)
        for i in range(chain.n_joints):
            dq = np.zeros(chain.n_joints)
            dq[i] = h
            Tp, Tm = chain.forward_kinematics(q + dq), chain.forward_kinematics(q - dq)
            v = (Tp[:3, 3] - Tm[:3, 3]) / (2 * h)
            w = (Rotation.from_matrix(Tp[:3, :3] @ T[:3, :3].T).as_rotvec()
                 - Rotation.from_matrix(Tm[:3, :3] @ T[:3, :3].T).as_rotvec()) / (2 * h)
            np.testing.assert_allclose(J[:3, i], v, atol=2e-5 * max(1.0, np.abs(v).max()))
            np.testing.assert_allclose(J[3:, i], w, atol=1e-7)


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), shape=st.sampled_from([(1,), (7,), (3, 4), (2, 1, 5)]))
def test_batch_equals_stacked_singles(seed, shape):
    chain = robot_model("ur10")
    qs = np.random.default_rng(seed).uniform(-4.0, 4.0, shape + (6,))
    T, J = chain.forward_kinematics_and_jacobian(qs)
    assert T.shape == shape + (4, 4) and J.shape == shape + (6, 6)
    flat_q = qs.reshape(-1, 6)
    singles = [chain.forward_kinematics_and_jacobian(q) for q in flat_q]
    np.testing.assert_array_equal(T.reshape(-1, 4, 4), np.stack([s[0] for s in singles]))
    np.testing.assert_array_equal(J.reshape(-1, 6, 6), np.stack([s[1] for s in singles]))
    np.testing.assert_array_equal(chain.forward_kinematics(qs), T)
    np.testing.assert_array_equal(chain.geometric_jacobian(qs, check=False), J)


def test_tool_and_flange(skewed_path):
    tool = np.eye(4)
    tool[:3, 3] = [0.0, 0.0, 120.0]
    chain = load_urdf(skewed_path, "world", "tcp", T_flange_tool=tool)
    q = np.array([0.1, -0.2, 30.0, 0.4, -0.5, 0.6])
    np.testing.assert_allclose(chain.forward_kinematics(q), reference_fk(q) @ tool, atol=1e-9)
    np.testing.assert_allclose(chain.forward_kinematics(q, tool=False), reference_fk(q), atol=1e-9)
    np.testing.assert_allclose(chain.with_tool(np.eye(4)).forward_kinematics(q), reference_fk(q), atol=1e-9)


def test_sub_chain_between_inner_links(skewed_path):
    """base_link/tip_link pick any path: l1 -> l5 has j2, slide, j4, j5."""
    chain = load_urdf(skewed_path, "l1", "l5")
    assert chain.joint_names == ("j2", "slide", "j4", "j5")
    q_full = np.array([0.7, 0.1, 25.0, -0.3, 0.9, 0.0])
    # T_l1_l5 = T_world_l1^-1 T_world_l5 from the full chains
    T_w_l1 = load_urdf(skewed_path, "world", "l1").forward_kinematics(q_full[:1])
    T_w_l5 = load_urdf(skewed_path, "world", "l5").forward_kinematics(q_full[:5])
    np.testing.assert_allclose(chain.forward_kinematics(q_full[1:5]), np.linalg.inv(T_w_l1) @ T_w_l5, atol=1e-9)


def test_dh_chain_is_a_serial_chain_with_the_same_pack():
    """A DH table through SerialChain (origins = the rows at zero) gives the same kinematics."""
    dh = puma560()
    M, A = dh.kinematic_pack
    general = SerialChain(M[:-1], A[:, :3], dh.joint_types, T_last_flange=M[-1])
    qs = _random_q(dh, np.random.default_rng(6), 20)
    np.testing.assert_array_equal(general.forward_kinematics(qs), dh.forward_kinematics(qs))


def test_perturbed_urdf_chain_is_close_but_not_equal():
    chain = robot_model("ur10")
    true = chain.perturbed(0.3, math.radians(0.05), np.random.default_rng(0))
    q = _random_q(chain, np.random.default_rng(7), 50)
    d = np.linalg.norm(true.forward_kinematics(q)[:, :3, 3] - chain.forward_kinematics(q)[:, :3, 3], axis=1)
    assert 0.2 < np.median(d) < 5.0
    assert true.name == "ur10 (true)" and true.joint_names == chain.joint_names


# --------------------------------------------------------------------------- bad input

def _write(tmp_path, text, name="bad.urdf"):
    p = tmp_path / name
    p.write_text(text)
    return p


ARM = """<robot name="arm"><link name="base"/><link name="a"/><link name="b"/>
<joint name="j1" type="revolute"><parent link="base"/><child link="a"/>{axis1}<limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
<joint name="j2" type="{type2}"><parent link="a"/><child link="b"/>{extra2}</joint>
{more}</robot>"""


def _arm(axis1='<axis xyz="0 0 1"/>', type2="revolute", extra2='<axis xyz="0 1 0"/>', more=""):
    return ARM.format(axis1=axis1, type2=type2, extra2=extra2, more=more)


@pytest.mark.parametrize(
    ("text", "kwargs", "match"),
    [
        ("<robot name='x'><link name='a'>", {}, r"bad\.urdf: malformed XML: .*expected a URDF file"),
        ("not xml at all", {}, r"bad\.urdf: malformed XML"),
        ("<model name='x'/>", {}, r"bad\.urdf: root element <model>; expected a URDF <robot> element"),
        (_arm(), {"base_link": "floor"},
         r"bad\.urdf: unknown base_link 'floor'; the file's links are base, a, b"),
        (_arm(), {"tip_link": "hand"}, r"bad\.urdf: unknown tip_link 'hand'; the file's links are base, a, b"),
        (_arm(), {"base_link": "b", "tip_link": "a"},
         r"bad\.urdf: tip_link 'a' is not below base_link 'b'; expected a tip link on a path down from the base"),
        (_arm(axis1='<axis xyz="0 0 0"/>'), {}, r"bad\.urdf: joint 'j1': axis \[0\.0, 0\.0, 0\.0\]; expected a non-zero"),
        (_arm(extra2='<axis xyz="0 1 0"/><mimic joint="j1" multiplier="2"/>'), {"tip_link": "b"},
         r"bad\.urdf: joint 'j2': unsupported: mimic joint on the chain \(mimics 'j1'\)"),
        (_arm(type2="floating", extra2=""), {"tip_link": "b"},
         r"bad\.urdf: joint 'j2': unsupported type 'floating' on the chain"),
        (_arm(more='<joint name="loop" type="fixed"><parent link="base"/><child link="b"/></joint>'), {},
         r"bad\.urdf: unsupported URDF: closed loop \(link 'b' is the child of joints 'j2' and 'loop'\)"),
        (_arm(more='<joint name="j3" type="fixed"><parent link="a"/><child link="ghost"/></joint>'), {},
         r"bad\.urdf: joint 'j3': child link 'ghost' is not defined"),
        ('<!DOCTYPE r [<!ENTITY a "aaaa">]><robot name="x"><link name="&a;"/></robot>', {},
         r"bad\.urdf: unsupported URDF: DTD entities"),
        ('<robot name="x" xmlns:xacro="http://ros.org/wiki/xacro"><xacro:property name="a" value="1"/></robot>', {},
         r"bad\.urdf: a xacro file \(element <property> of the xacro namespace\); expected plain URDF \(run xacro first\)$"),
        ('<robot name="x"><xacro:include filename="arm.xacro"/></robot>', {},      # prefix never declared
         r"bad\.urdf: a xacro file \(element <xacro:include> of the xacro namespace\)"),
        (_arm(extra2='<axis xyz="0 1 0"/><origin xyz="0 0 ${l2}"/>'), {},
         r"bad\.urdf: a xacro file \(joint 'j2' has the expression '0 0 \$\{l2\}'\); expected plain URDF"),
        (_arm(extra2='<axis xyz="0 1 0"/><origin xyz="$(arg x) 0 0"/>'), {},
         r"bad\.urdf: a xacro file \(joint 'j2' has the expression '\$\(arg x\) 0 0'\)"),
        ('<robot name="x"><link name="a"/><link/></robot>', {},
         r"bad\.urdf: <link> number 2 of <robot> has no name attribute; expected name=\"\.\.\.\"$"),
        (_arm(extra2='<axis xyz="0 1 0"/><origin xyz="1e300 0 0"/>'), {},
         r"bad\.urdf: joint 'j2': origin xyz 1e\+300 m from its parent; expected metres within 10000 m$"),
        (_arm(extra2='<axis xyz="0 1 0"/><limit lower="nan" upper="1" effort="1" velocity="1"/>'), {},
         r"bad\.urdf: joint 'j2': limit lower nan > upper 1 \(or NaN\); expected lower <= upper$"),
        (_arm(extra2='<axis xyz="0 1 0"/><limit lower="2" upper="1" effort="1" velocity="1"/>'), {},
         r"bad\.urdf: joint 'j2': limit lower 2 > upper 1"),
        (_arm(extra2='<axis xyz="0 1 0"/><origin xyz="1 2"/>'), {},
         r"bad\.urdf: malformed URDF \(ValueError"),
        (_arm(extra2='<axis xyz="0 1 0"/><origin xyz="nan 0 0"/>'), {},
         r"bad\.urdf: joint 'j2': origin xyz/rpy must be 3 finite numbers each"),
        ('<robot name="x"><link name="a"/><link name="b"/><joint name="f" type="fixed"><parent link="a"/>'
         '<child link="b"/></joint></robot>', {}, r"bad\.urdf: no arm joint below base_link 'a' \(mimic and "
                                                  r"gripper joints do not count\); expected a serial arm, or pass tip_link"),
    ],
)
def test_bad_urdf(tmp_path, text, kwargs, match):
    with pytest.raises(ConfigError, match=match) as info:
        load_urdf(_write(tmp_path, text), **kwargs)
    assert "\n" not in str(info.value)


def test_missing_and_oversized_files(tmp_path, monkeypatch):
    with pytest.raises(ConfigError, match=r"nope\.urdf: no such URDF file"):
        load_urdf(tmp_path / "nope.urdf")
    with pytest.raises(ConfigError, match=r"is a folder; expected a URDF file"):
        load_urdf(tmp_path)
    from posekit.robots import urdf

    monkeypatch.setattr(urdf, "MAX_URDF_BYTES", 100)
    with pytest.raises(ConfigError, match=r"big\.urdf: .* MiB, above the .* MiB limit for a URDF file"):
        load_urdf(_write(tmp_path, _arm(), "big.urdf"))


@pytest.mark.parametrize(
    ("q", "match"),
    [
        (np.zeros(5), r"ur10: q must have shape \(6,\) or \(\.\.\., 6\), got shape \(5,\)"),
        (np.zeros(()), r"ur10: q must have shape \(6,\) or \(\.\.\., 6\), got shape \(\)"),
        (np.r_[np.zeros(5), np.nan], r"ur10: q must be finite, found NaN or inf at index \[5\]"),
        ([[0.0] * 6, [0.0] * 5 + [np.inf]], r"ur10: q must be finite, found NaN or inf at index \[1, 5\]"),
        ("abc", r"ur10: q must be numeric, got str"),
    ],
)
def test_bad_q(q, match):
    chain = robot_model("ur10")
    for fn in (chain.forward_kinematics, chain.geometric_jacobian, chain.forward_kinematics_and_jacobian,
               chain.joint_axes):
        with pytest.raises(ConfigError, match=match):
            fn(q)


def test_ambiguous_default_tip(tmp_path):
    text = _arm(more='<link name="c"/><joint name="j3" type="revolute"><parent link="a"/><child link="c"/>'
                     '<axis xyz="1 0 0"/></joint>')
    with pytest.raises(ConfigError, match=r"the default tip is ambiguous: the tree branches at 'a' into 2 chains of "
                                          r"1 moving joints; candidate tips 'b', 'c'; pass tip_link \(--tip-link\)$"):
        load_urdf(_write(tmp_path, text))
    assert load_urdf(_write(tmp_path, text), tip_link="c").joint_names == ("j1", "j3")


# --------------------------------------------------------------------------- the world's URDF

def test_what_pinocchio_reads_loads(tmp_path):
    """xacro leftovers in comments, unnamed joints inside <gazebo>, plugins, transmissions and an
    undeclared namespace prefix inside a gazebo block are outside the kinematic tree."""
    more = ('<!-- origin was ${pi/2} in the xacro --><gazebo><plugin name="p" filename="x.so"><joint>j1</joint>'
            '</plugin><sensor:camera name="c"/></gazebo>'
            '<transmission name="t"><joint name="j1"/><actuator name="m"/></transmission>'
            '<gazebo reference="a"><joint/></gazebo>')
    path = _write(tmp_path, _arm(extra2='<axis xyz="0 1 0"/><limit lower="-2" upper="2" effort="1" velocity="1"/>',
                                 more=more), "world.urdf")
    chain = load_urdf(path)
    assert (chain.base_link, chain.tip_link, chain.joint_names) == ("base", "b", ("j1", "j2"))
    pin.buildModelFromUrdf(str(path))                          # the reference reads it too
    q = np.array([0.3, -0.4])
    T_pin, J_pin = PinocchioChain(path, chain)(q)
    np.testing.assert_allclose(chain.forward_kinematics(q), T_pin, atol=1e-9)
    np.testing.assert_allclose(chain.geometric_jacobian(q), J_pin, atol=1e-9)


def test_infinite_limits_are_unbounded_and_said(tmp_path):
    text = _arm(extra2='<axis xyz="0 1 0"/><limit lower="-inf" upper="inf" effort="1" velocity="1"/>')
    chain = load_urdf(_write(tmp_path, text), tip_link="b")
    assert chain.q_min[1] == -np.inf and chain.q_max[1] == np.inf
    assert chain.notes == ("joint 'j2': limit -inf..inf read as unbounded",)
    assert chain.within_limits([0.0, 1e6])


def test_huge_axis_components_do_not_overflow(tmp_path):
    chain = load_urdf(_write(tmp_path, _arm(extra2='<axis xyz="1e300 1e300 0"/>')), tip_link="b")
    np.testing.assert_allclose(chain.axes[1], [2 ** -0.5, 2 ** -0.5, 0.0])


def test_default_tip_is_linear_on_a_long_chain():
    """45,000 links (the most a 16 MB file holds): a chain with a side link per joint. A search per
    leaf is quadratic (37 s at 16,000 links before); the walk is one pass, and never recursion."""
    from types import SimpleNamespace

    from posekit.robots._urdf_tree import JointTree

    n = 22_500
    joints = []
    for i in range(1, n):
        joints.append(SimpleNamespace(name=f"j{i}", type="revolute", parent=f"l{i - 1}", child=f"l{i}", mimic=None))
        joints.append(SimpleNamespace(name=f"f{i}", type="fixed", parent=f"l{i - 1}", child=f"s{i}", mimic=None))
    links = [f"l{i}" for i in range(n)] + [f"s{i}" for i in range(1, n)]
    tree = JointTree("big.urdf", links, joints)
    found = tree.default_tip(tree.root())
    assert (found.tip, found.how) == (f"l{n - 1}", "end")
    assert len(tree.path_joints("l0", found.tip)) == n - 1
