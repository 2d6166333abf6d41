"""What an operator may change of the guiding law (``GuidingController.adjust``): the same
cycles as a controller built with those settings, clamped to the operator limits, refused while
guiding and for settings the law does not have."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from leadthrough.control import GuidingConfig, GuidingController, State
from leadthrough.control.guiding_types import adjusted_config
from leadthrough.control.operator_limits import OperatorLimits
from leadthrough.control.virtual_friction import VirtualFrictionConfig
from leadthrough.errors import ControlError
from leadthrough.robot import Robot

Q_WORK = np.array([0.0, -0.6, 0.9, 0.0, 0.8, 0.0])


def cycles(ctl: GuidingController, wrench: np.ndarray, held: bool = True) -> np.ndarray:
    """Commanded joint positions of ``len(wrench)`` cycles from Q_WORK with a perfect servo
    (the deadman released in the first cycle, then ``held``)."""
    ctl.reset(Q_WORK)
    inp, out = ctl.make_input(), ctl.make_output()
    inp.q[:] = Q_WORK
    qs = np.zeros((len(wrench), ctl.n))
    for k, w in enumerate(wrench):
        inp.t, inp.sequence, inp.deadman = 0.01 * k, k, held and k > 0
        inp.wrench_base[:] = w
        ctl.update(inp, out)
        qs[k] = out.q
        inp.q[:] = out.q
    return qs


def push(k: int = 150) -> np.ndarray:
    """A push along x, y and about z, 40 N and 30 N·m (exceeds any friction in range)."""
    w = np.zeros((k, 6))
    w[10:, :3] = (40.0, -25.0, 10.0)
    w[10:, 5] = 30.0
    return w


def test_adjusted_controller_runs_the_cycles_of_one_built_with_those_settings(
        er20: Robot) -> None:
    base = GuidingConfig()
    adjusted = GuidingController(er20, base)
    cfg = adjusted.adjust(frame="tool", axes_enabled=(True, False, True, False, False, True),
                          mass=(300.0, 400.0), friction=(20.0, 8.0))
    built = GuidingController(er20, replace(
        base, frame="tool", axes_enabled=(True, False, True, False, False, True),
        virtual_friction=VirtualFrictionConfig(mass=(300.0,) * 3 + (400.0,) * 3,
                                               friction=(20.0,) * 3 + (8.0,) * 3,
                                               stopping_friction=(50.0,) * 6)))
    assert cfg == built.config == adjusted.config
    a, b = cycles(adjusted, push()), cycles(built, push())
    assert np.array_equal(a, b)
    assert np.abs(a[-1] - a[0]).max() > 1e-3           # it moved


def test_mass_and_friction_are_clamped_to_the_operator_limits(er20: Robot) -> None:
    lim = OperatorLimits(linear_mass=(80.0, 900.0), angular_friction=(4.0, 20.0))
    ctl = GuidingController(er20, GuidingConfig(operator_limits=lim))
    cfg = ctl.adjust(mass=(1.0, 1e9), friction=(1000.0, 0.0))
    vf = cfg.virtual_friction
    assert vf.mass == (80.0,) * 3 + (lim.angular_mass[1],) * 3
    assert vf.friction == (lim.linear_friction[1],) * 3 + (4.0,) * 3
    # the stopping friction stays the commissioned one, raised to δ where δ exceeds it
    assert vf.stopping_friction == (60.0,) * 3 + (50.0,) * 3


@settings(max_examples=60, deadline=None)
@given(st.floats(-1e6, 1e6), st.floats(-1e6, 1e6))
def test_clamped_values_lie_within_the_bounds(linear: float, angular: float) -> None:
    lim = OperatorLimits()
    m, i = lim.clamp_mass(linear, angular)
    f, t = lim.clamp_friction(linear, angular)
    assert lim.linear_mass[0] <= m <= lim.linear_mass[1]
    assert lim.angular_mass[0] <= i <= lim.angular_mass[1]
    assert lim.linear_friction[0] <= f <= lim.linear_friction[1]
    assert lim.angular_friction[0] <= t <= lim.angular_friction[1]
    inside = lim.linear_mass[0] <= linear <= lim.linear_mass[1]
    assert (m == linear) == inside


def test_settings_do_not_change_while_guiding(er20: Robot) -> None:
    ctl = GuidingController(er20)
    cycles(ctl, push(30))
    assert ctl.state == State.GUIDING
    before = ctl.config
    with pytest.raises(ControlError, match="state"):
        ctl.adjust(frame="tool")
    assert ctl.config is before
    cycles(ctl, np.zeros((3, 6)), held=False)          # released: IDLE
    assert ctl.state == State.IDLE
    assert ctl.adjust(frame="tool").frame == "tool"


@pytest.mark.parametrize(("change", "config", "field"), [
    ({"mass": (100.0, 100.0)}, {"controller": "velocity"}, "mass"),
    ({"friction": (20.0, 5.0)}, {"friction_mode": "auto"}, "friction"),
    ({"mass": (math.nan, 100.0)}, {}, "mass.linear"),
    ({"axes_enabled": (True,) * 5}, {}, "axes_enabled"),
    ({"frame": "world"}, {}, "frame"),
])
def test_refused_changes_name_the_field(er20: Robot, change: dict[str, object],
                                        config: dict[str, object], field: str) -> None:
    cfg = replace(GuidingConfig(), **config)
    noise = np.full(er20.n, 0.5)
    ctl = GuidingController(er20, cfg, noise, noise)
    with pytest.raises(ControlError, match=field):
        ctl.adjust(**change)  # type: ignore[arg-type]
    assert ctl.config == cfg


def test_bad_operator_limits_are_refused() -> None:
    with pytest.raises(ControlError, match=r"operator_limits\.linear_mass"):
        OperatorLimits(linear_mass=(0.0, 10.0))
    with pytest.raises(ControlError, match=r"operator_limits\.angular_friction"):
        OperatorLimits(angular_friction=(5.0, 1.0))
    assert adjusted_config(GuidingConfig(), GuidingConfig()) == GuidingConfig()
