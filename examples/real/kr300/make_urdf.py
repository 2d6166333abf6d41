"""Write kr300.urdf from the KUKA KR300 R2500 ultra facts of ../shared/data/kr300/facts.toml.

The source is a standard-DH Robotics Toolbox model (Weigand et al., MIT licence):
A_i = Rz(θ_i)·Tz(d_i)·Tx(a_i)·Rx(α_i), base trotx(180°), tool troty(−90°). In the URDF, joint i
turns about z at the origin of DH frame i−1; the fixed part Tz(d)·Tx(a)·Rx(α) of link i−1 becomes
joint i's origin, and link i's CoM and inertia (given in DH frame i) are moved into the joint
frame. The URDF joint angle is the model angle θ_i = q_rel + qs + offset (see columns_*.toml).

Nominal link 6 adds the feed-forward payload of the source (150 kg at 0.1 m along link-6 z, as a
solid sphere of radius 0.15 m) to the bare axis-6 mass (17.78 kg point mass at −0.05 m): the
recordings carry an undocumented payload of about that size.

    python examples/real/kr300/make_urdf.py [facts.toml]
"""

from __future__ import annotations

import math
import sys
import tomllib
import warnings
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

HERE = Path(__file__).resolve().parent
FACTS = HERE.parents[2].parent / "shared" / "data" / "kr300" / "facts.toml"


def _rot(axis: str, angle: float) -> np.ndarray:
    return Rotation.from_euler(axis, angle).as_matrix()


def _fixed(d: float, a: float, alpha: float) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = _rot("x", alpha)
    T[:3, 3] = [a, 0.0, d]
    return T


def _origin(T: np.ndarray) -> str:
    with warnings.catch_warnings():  # pitch ±90°: any split of roll/yaw is the same rotation
        warnings.simplefilter("ignore", UserWarning)
        rpy = Rotation.from_matrix(T[:3, :3]).as_euler("xyz")
    assert np.allclose(Rotation.from_euler("xyz", rpy).as_matrix(), T[:3, :3], atol=1e-12)
    xyz = " ".join(f"{v:.12g}" for v in T[:3, 3])
    return f'<origin xyz="{xyz}" rpy="{" ".join(f"{v:.12g}" for v in rpy)}"/>'


def _inertial(mass: float, com: np.ndarray, inertia: np.ndarray) -> str:
    i = inertia
    return (f'    <inertial>\n      <origin xyz="{" ".join(f"{v:.12g}" for v in com)}" '
            f'rpy="0 0 0"/>\n      <mass value="{mass:.12g}"/>\n'
            f'      <inertia ixx="{i[0, 0]:.12g}" ixy="{i[0, 1]:.12g}" ixz="{i[0, 2]:.12g}" '
            f'iyy="{i[1, 1]:.12g}" iyz="{i[1, 2]:.12g}" izz="{i[2, 2]:.12g}"/>\n    </inertial>')


def main() -> None:
    facts_path = Path(sys.argv[1]) if len(sys.argv) > 1 else FACTS
    f = tomllib.loads(facts_path.read_text())
    d, a, alpha = f["dh"]["d"], f["dh"]["a"], f["dh"]["alpha"]
    masses, coms = f["links"]["mass"], f["links"]["com"]
    inertias = f["links"]["inertia"]
    lims = f["convention"]["qlim_deg"]
    pl = f["payload"]
    lines = ['<?xml version="1.0"?>',
             "<!-- KUKA KR300 R2500 ultra from the standard-DH model of Weigand et al. (MIT),",
             "     written by examples/real/kr300/make_urdf.py; see its docstring. -->",
             '<robot name="kr300">', '  <link name="base_link"/>']
    parent = "base_link"
    prev_fixed = np.eye(4)
    prev_fixed[:3, :3] = _rot("x", math.pi)  # base trotx(180°)
    for i in range(6):
        Ti = _fixed(d[i], a[i], alpha[i])
        m = masses[i]
        com = np.array(coms[i])
        ixx, iyy, izz, ixy, iyz, ixz = inertias[i]
        I_c = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
        if i == 5:
            mp, zp = pl["m_payload_feedforward"], pl["r_payload_z"]
            m6, z6 = pl["m_axis6"], pl["r_axis6_z"]
            m = m6 + mp
            com = np.array([0.0, 0.0, (m6 * z6 + mp * zp) / m])
            sphere = 0.4 * mp * 0.15**2 * np.eye(3)
            # parallel axis: both point masses / sphere about the combined CoM (z only)
            I_c = sphere.copy()
            for mk, zk in ((m6, z6), (mp, zp)):
                dz = zk - com[2]
                I_c += mk * dz**2 * np.diag([1.0, 1.0, 0.0])
        # link frame = DH frame i before its fixed part: move CoM/inertia by Ti
        com_j = Ti[:3, :3] @ com + Ti[:3, 3]
        I_j = Ti[:3, :3] @ I_c @ Ti[:3, :3].T
        link = f"link_{i + 1}"
        lines.append(f'  <link name="{link}">\n{_inertial(m, com_j, I_j)}\n  </link>')
        lo, hi = (math.radians(v) for v in lims[i])
        lines.append(f'  <joint name="joint_{i + 1}" type="revolute">\n'
                     f'    <parent link="{parent}"/>\n    <child link="{link}"/>\n'
                     f'    {_origin(prev_fixed)}\n    <axis xyz="0 0 1"/>\n'
                     f'    <limit lower="{lo!r}" upper="{hi!r}" effort="10000" velocity="3"/>\n'
                     "  </joint>")
        parent = link
        prev_fixed = Ti
    tool = prev_fixed.copy()
    tool[:3, :3] = tool[:3, :3] @ _rot("y", -math.pi / 2)  # tool troty(−90°)
    lines.append('  <link name="flange"/>')
    lines.append(f'  <joint name="flange_fixed" type="fixed">\n    <parent link="{parent}"/>\n'
                 f'    <child link="flange"/>\n    {_origin(tool)}\n  </joint>')
    lines.append("</robot>")
    (HERE / "kr300.urdf").write_text("\n".join(lines) + "\n")
    print(f"wrote {HERE / 'kr300.urdf'}")


if __name__ == "__main__":
    main()
