"""The dress pack of a welding robot: hoses and cables along the arm that no CAD model carries.

A welding robot carries its torch cable, gas hose and wire feed along the upper arm and the
forearm, clamped a hand's width off the structure. The realistic plant adds that mass to the
two longest links (the upper arm and the forearm: the largest distance from a joint to the
next) as a solid cylinder along each link, offset sideways from the line joining the two joint
origins::

    mass         = fraction · (nominal mass of the two links), split between them
    cylinder     : from s₀ to s₁ of the way to the next joint, radius r, axis along the link
    offset       : d perpendicular to the link, in a direction drawn around it

On the er20 (38 kg upper arm, 18 kg forearm) the default draws 2.8–5.6 kg in all. The
identification model has no such term: it can only absorb the pack into the links' parameters,
where it moves the mass, the centre of mass and the inertia of both links.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

from leadthrough.errors import SimulationError
from leadthrough.sim.plant import check_draw_ranges

__all__ = ["DressPackConfig", "arm_links", "dress_pack_inertias"]


@dataclass(frozen=True)
class DressPackConfig:
    """How the dress pack is drawn (each range is sampled uniformly per robot instance).

    Attributes:
        mass_fraction: Pack mass as a fraction of the two arm links' nominal mass [-].
        upper_arm_share: Share of the pack's mass on the upper arm (the rest on the forearm) [-].
        offset: Distance of the pack's axis from the link's centre line [m].
        radius: Radius of the cylinder the pack's mass fills [m].
        start: Where the pack starts, as a fraction of the way to the next joint [-].
        end: Where the pack ends, likewise [-].
    """

    mass_fraction: tuple[float, float] = (0.05, 0.10)
    upper_arm_share: tuple[float, float] = (0.4, 0.6)
    offset: tuple[float, float] = (0.08, 0.15)
    radius: float = 0.03
    start: float = 0.15
    end: float = 0.85

    def __post_init__(self) -> None:
        check_draw_ranges("dress_pack", self)
        if self.mass_fraction[1] >= 1.0 or self.upper_arm_share[1] > 1.0:
            raise SimulationError("fraction out of range", field="dress_pack.mass_fraction",
                                  value=(self.mass_fraction, self.upper_arm_share),
                                  expected="mass fraction < 1 and share <= 1")
        if not 0.0 <= self.start < self.end <= 1.0:
            raise SimulationError("bad extent", field="dress_pack.start/end",
                                  value=(self.start, self.end), expected="0 <= start < end <= 1")


def arm_links(model: pin.Model) -> tuple[int, int]:
    """The upper arm and the forearm: the two links (joint indices 1..n−1, in chain order) with
    the largest distance from their joint to the next joint's origin."""
    n = model.njoints - 1
    if n < 3:
        raise SimulationError("a dress pack needs an arm", field="robot.joints", value=n,
                              expected="at least 3 joints")
    length = [float(np.linalg.norm(model.jointPlacements[j + 1].translation))
              for j in range(1, n)]
    first, second = sorted(np.argsort(length)[-2:] + 1)
    return int(first), int(second)


def _perpendicular(axis: NDArray[np.float64], angle: float) -> NDArray[np.float64]:
    """A unit vector perpendicular to the unit vector ``axis``, at ``angle`` around it."""
    helper = np.eye(3)[int(np.argmin(np.abs(axis)))]
    e1 = np.cross(axis, helper)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(axis, e1)
    return np.cos(angle) * e1 + np.sin(angle) * e2


def _segment_inertia(mass: float, a: NDArray[np.float64], b: NDArray[np.float64],
                     radius: float) -> pin.Inertia:
    """A solid cylinder of ``mass`` from point a to point b (joint frame) [kg, m]."""
    axis = (b - a) / np.linalg.norm(b - a)
    z = np.array([0.0, 0.0, 1.0])
    rot = pin.Quaternion.FromTwoVectors(z, axis).matrix()
    cylinder = pin.Inertia.FromCylinder(mass, radius, float(np.linalg.norm(b - a)))
    return pin.SE3(rot, 0.5 * (a + b)).act(cylinder)


def dress_pack_inertias(model: pin.Model, config: DressPackConfig, rng: np.random.Generator
                        ) -> dict[int, pin.Inertia]:
    """Draw a dress pack: its inertia on the upper arm and the forearm.

    Args:
        model: The robot's nominal Pinocchio model.
        config: How the pack is drawn.
        rng: Random generator (of the robot instance).

    Returns:
        Joint index → the pack's inertia in that joint's frame (to add to the link's).
    """
    links = arm_links(model)
    mass = rng.uniform(*config.mass_fraction) * sum(float(model.inertias[j].mass)
                                                    for j in links)
    share = rng.uniform(*config.upper_arm_share)
    out: dict[int, pin.Inertia] = {}
    for j, part in zip(links, (share, 1.0 - share), strict=True):
        tip = np.asarray(model.jointPlacements[j + 1].translation, dtype=float)
        axis = tip / np.linalg.norm(tip)
        side = rng.uniform(*config.offset) * _perpendicular(axis,
                                                            rng.uniform(0.0, 2.0 * np.pi))
        out[j] = _segment_inertia(part * mass, config.start * tip + side,
                                  config.end * tip + side, config.radius)
    return out
