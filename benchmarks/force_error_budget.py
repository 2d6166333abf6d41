"""Where the force estimate's error in motion comes from (issue 24, must show 4), per source.

    python benchmarks/force_error_budget.py [--instances 3,4,5] [--operators push-x,seam]
                                            [--plant realistic|ideal] [--hand-release]
                                            [--cache DIR]

(``--operators random:14 --hand-release``: ``run_on.py``'s random session with operator seed
14.)

Each robot instance is calibrated as ``benchmarks/run_on.py`` does (60 s excitation and a
friction sweep, ``consistent``; cached under ``--cache``), then runs the guiding benchmark's
sessions with its settings (``benchmarks/guiding.py`` sections 2 and 3: the paper's law; push-x
with 100 kg translational virtual mass, the diagonal and the seam with the defaults). Every
servo period the simulator's truth is read beside the estimator's state, and the estimate's
joint-torque error τ̂_ext − τ_ext splits exactly into four parts:

* **friction**: the estimator's friction torque τ̂_f minus the plant's (bristles, Coulomb,
  Stribeck, load, ripple and viscous), through the estimator's output low-pass;
* **rigid body and drive, after the re-zero**: the identified links, rotor inertias and
  offsets minus the plant's link torque, both at the plant's state, plus the torque the
  plant's
  motors make minus τ̂_j = R·Kt·i (the torque constant's error, cogging, the currents' lag
  and noise), low-passed, plus the identified mean noise τ̄_ω and minus the re-zero's tare
  (which takes up the first two at each re-zero's pose);
* **state lag**: the identified model at the estimator's filtered q, q̇, q̈ minus at the
  plant's (the differentiator's lag and noise, the encoder's resolution);
* **output filter**: the low-pass of the true τ_ext minus τ_ext (the 3 Hz filter's lag).

Each part is mapped to a force by the estimator's own fit at that sample (its per-joint
weights, Jacobian and damping: the fit is linear in τ for given weights), and the mapping's
own error (the fit of the true τ_ext against the applied force) is a fifth line. The parts
add up to the estimated minus the applied force; the script checks that they do.

**The current sensing's floor.** With a perfect model (links, friction, drives and state all
exact, and the current's lag behind the positions known) the estimate would still hold the
current sensor's error, R·Kt·(i_measured − i_true) with i_true taken at the instant the
sample was taken (the white noise, the slowly varying error in motion, the bias and the ADC:
:mod:`leadthrough.sim.sensors`), through the output filter, plus the filter's lag. The script
prints that floor through the same fit, the RMS in motion and the largest phantom after a
release (as ``phantom_forces``), for the estimator's own filter and for each filter of
``_floor_filters`` (first order 1–4.5 Hz, Butterworth and Bessel of second order,
Butterworth of fourth order). No model can take the sensor's error out: in motion it is
slow (50 ms correlation), inside the band of the hand's force. (The estimator's filter's
floor without the sensor's error is the output filter's part; the script checks that.)

Printed per instance and session: the RMS in motion (commanded TCP speed >= 0.02 m/s, as
``force_error_in_motion``) of the total, of each part, and of the total without each part (the
error if that source were perfect; the parts are correlated, so these do not add in
quadrature); then the friction part by joint, and the floor. Issue 24's goals are 5 N in
motion and a phantom ≤ δ = 15 N. The truth is read only to report the error against it.
"""

from __future__ import annotations

import argparse
import tempfile
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import pinocchio as pin
import scipy.signal
from numpy.typing import NDArray

from leadthrough.control.hand_release import HandReleaseConfig
from leadthrough.drivers.protocol import Driver, DriverFeedback, WrappedDriver
from leadthrough.estimation.estimator import ExternalForceEstimator
from leadthrough.estimation.filters import low_pass_alpha
from leadthrough.estimation.wrench import wrench_from_torque
from leadthrough.robot import Robot, load_robot
from leadthrough.session.loop_config import LoopConfig, LoopParts
from leadthrough.session.metrics import MOTION_SPEED, PHANTOM_WINDOW_S, hands_off_intervals
from leadthrough.session_format import SessionLog
from leadthrough.sim.driver import SimDriver
from leadthrough.sim.plant import PLANT_NAMES
from leadthrough.sim.session import SimSessionConfig, light_guiding, run_sim_session
from run_on import calibrated

Array = NDArray[np.float64]

#: The parts, in print order.
PARTS = ("friction", "rigid body + drive", "state lag", "output filter", "force fit")

#: Sessions that ``benchmarks/guiding.py`` runs with the default guiding settings (section 3).
PATHS = ("diagonal", "seam")

#: A joint slower than this [rad/s] is near standstill or reversing: its friction is in its
#: presliding transient or held, not on the steady curve the sweep measured.
SLOW_JOINT = 0.01


@dataclass
class Samples:
    """Per servo period: the plant's truth after the step, and the estimator's state after its
    update of the same sample (one list entry per period)."""

    friction: list[Array] = field(default_factory=list)    # all of the plant's friction
    state: list[Array] = field(default_factory=list)       # the step's q, q̇, q̈ (3, n)
    external: list[Array] = field(default_factory=list)    # J^T F of the operator
    applied: list[Array] = field(default_factory=list)     # F [N], base axes
    sensing: list[Array] = field(default_factory=list)     # the current sensor's error [N·m]
    q: list[Array] = field(default_factory=list)           # measured q (to align)
    estimator: list[dict[str, Array]] = field(default_factory=list)


#: Estimator record fields kept per sample.
_STATE = ("q_filtered", "qd_filtered", "qdd_filtered", "friction_torque", "drive_torque",
          "joint_weight", "tare", "noise_mean", "last_tau_ext", "last_wrench", "last_q")


class BudgetProbe(WrappedDriver):
    """Reads the simulator's truth at every read, and the estimator's state left by the
    previous period's update (so the state of update k is taken at read k + 1)."""

    def __init__(self, driver: Driver, samples: Samples) -> None:
        super().__init__(driver)
        if not isinstance(driver, SimDriver):
            raise TypeError("the budget needs the simulator's driver")
        self._sim = driver.sim
        self._out = samples
        self.estimator: ExternalForceEstimator | None = None
        self._reads = 0

    def read(self, fb: DriverFeedback) -> bool:
        est = self.estimator
        if est is not None and self._reads > 0:
            rec = est.record
            self._out.estimator.append({k: np.array(rec[k][0]) for k in _STATE})
        fresh = self._driver.read(fb)
        self._reads += 1
        sim, out = self._sim, self._out
        out.friction.append(sim.true_total_friction)
        d, h = sim.mj_data, sim.mj_model.opt.timestep
        # the state the step's dynamics were evaluated at: before the (semi-implicit Euler)
        # integration, q⁺ = q + h·q̇⁺ and q̇⁺ = q̇ + h·q̈
        out.state.append(np.array([d.qpos - h * d.qvel, d.qvel - h * d.qacc, d.qacc]))
        out.external.append(sim.true_external_torque)
        out.applied.append(sim.applied_wrench[:3].copy())
        out.q.append(np.array(fb.q))
        out.sensing.append(sim.robot.torque_per_amp
                           * (np.asarray(fb.current) - sim.true_sampled_current))
        return fresh


@dataclass(frozen=True)
class Budget:
    """One session's budget: RMS in motion [N] of the total and of each part, and of the
    total without each part; the samples in motion; the check of the parts' sum [N]; the
    friction part's share from joints slower than ``SLOW_JOINT`` at that sample and from the
    others, and from each joint alone [N]."""

    total: float
    part: dict[str, float]
    without: dict[str, float]
    moving: int
    closure: float
    friction_slow: float = 0.0
    friction_sliding: float = 0.0
    friction_joint: tuple[float, ...] = ()
    floor: dict[str, Floor] = field(default_factory=dict)


def _low_pass(x: Array, alpha: float) -> Array:
    """The estimator's first-order low-pass, y_k = y_(k-1) + α·(x_k − y_(k-1)) from 0, per
    column."""
    return np.asarray(scipy.signal.lfilter([alpha], [1.0, alpha - 1.0], x, axis=0))


def _floor_filters(dt: float) -> dict[str, tuple[Array, Array]]:
    """The output filters the sensing floor is taken over (name: numerator, denominator), at
    the sample period ``dt`` [s]."""
    fs = 1.0 / dt
    out: dict[str, tuple[Array, Array]] = {}
    for fc in (1.0, 1.5, 2.0, 3.0, 4.5):
        a = low_pass_alpha(fc, dt)      # the estimator's first-order low-pass
        out[f"first order {fc:g} Hz"] = (np.array([a]), np.array([1.0, a - 1.0]))
    for fc in (1.5, 2.0, 3.0, 4.5, 6.0):
        out[f"Butterworth 2 {fc:g} Hz"] = scipy.signal.butter(2, fc, fs=fs)
    for fc in (2.0, 3.0, 4.5, 6.0):
        out[f"Bessel 2 {fc:g} Hz"] = scipy.signal.bessel(2, fc, fs=fs, norm="delay")
    for fc in (3.0, 4.5, 6.0):
        out[f"Butterworth 4 {fc:g} Hz"] = scipy.signal.butter(4, fc, fs=fs)
    return out


#: The keys of the estimator's own filter in :attr:`Budget.floor`: with the sensor's error,
#: and its lag alone (no sensor error).
OWN_FILTER, LAG_ALONE = "the estimator's", "the estimator's, lag alone"


def _fit(est: ExternalForceEstimator, jac: Array, weight: Array, tau: Array) -> Array:
    """The estimator's force fit of one joint torque, with the weights it used."""
    cfg = est.config
    wrench, gram, factor = np.zeros(6), np.zeros((6, 6)), np.zeros((6, 6))
    wrench_from_torque(jac, np.ascontiguousarray(tau), weight, True,
                       cfg.manipulability_threshold, cfg.max_damping, cfg.min_force_lever,
                       wrench, gram, factor)
    return wrench[:3].copy()


def _commanded_speed(log: SessionLog, f_est: Array) -> Array:
    """The log's commanded TCP speed at each sample [m/s] (as ``force_error_in_motion``),
    the log's rows found by their estimate."""
    speed = np.linalg.norm(log.twist_cmd_base[:, :3], axis=1)
    for shift in range(-4, 5):
        a, b = max(0, shift), min(len(log.time), f_est.shape[0] + shift)
        if b - a > f_est.shape[0] // 2 and np.array_equal(
                log.wrench_base[a:b, :3], f_est[a - shift:b - shift]):
            out = np.zeros(f_est.shape[0])
            out[a - shift:b - shift] = speed[a:b]
            return out
    raise RuntimeError("the log's rows do not match the estimator's samples")


def budget(robot: Robot, samples: Samples, est: ExternalForceEstimator, log: SessionLog,
           moving_speed: float = MOTION_SPEED) -> Budget:
    """Split the force error of a session's samples (see the module docstring)."""
    st = samples.estimator
    # the state of update k was taken at read k + 1: pair it with the truth of read k
    N = len(st)
    truth_q = np.array(samples.q[:N])
    state_q = np.array([s["last_q"] for s in st])
    if not np.array_equal(truth_q[1:], state_q[1:]):   # 0: the set-up's dry updates
        raise RuntimeError("the truth and the estimator's samples are not aligned")
    cfg = est.config
    if cfg.axes != "force" or cfg.frame != "base" or cfg.method != "direct":
        raise ValueError("the budget splits the direct estimator's force-only fit in base "
                         "axes (the guiding loop's)")
    fr_true = np.array(samples.friction[:N])
    ext, applied = np.array(samples.external[:N]), np.array(samples.applied[:N])
    mdl = est.model
    rec = est.record[0]
    rotor, offset, alpha = rec["rotor_inertia"], rec["offset"], float(rec["low_pass_alpha"])
    frame = pin.LOCAL_WORLD_ALIGNED
    link, at_truth = np.empty_like(ext), np.empty_like(ext)
    jac = np.empty((N, 6, robot.n))
    for k, s in enumerate(st):
        qf, qdf, qddf = s["q_filtered"], s["qd_filtered"], s["qdd_filtered"]
        link[k] = pin.rnea(mdl.model, mdl.data, qf, qdf, qddf) + rotor * qddf + offset
        q, qd, qdd = samples.state[k]
        at_truth[k] = pin.rnea(mdl.model, mdl.data, q, qd, qdd) + rotor * qdd + offset
        jac[k] = pin.computeFrameJacobian(mdl.model, mdl.data, qf, robot.tcp_frame_id, frame)
    fr_est = np.array([s["friction_torque"] for s in st])
    drive = np.array([s["drive_torque"] for s in st])
    # update k subtracts the tare as it was before it (a re-zero's end updates it after)
    shift = np.array([s["noise_mean"] - p["tare"] for s, p in zip(st, st[:1] + st[:-1],
                                                                   strict=True)])
    # The plant's motors balance its links, friction and the hand: R·Kt·i + cogging =
    # (M q̈ + bias) + friction − τ_ext. The rigid body and drive part, the identified links at
    # the plant's state minus the plant's plus the plant's motor torque minus R·Kt_file·i, is
    # then at_truth + friction_true − τ_ext − τ̂_j (the plant's motor torque cancels); the
    # state lag is the identified model at the filtered state minus at the plant's.
    tau_parts = {
        "friction": _low_pass(fr_est - fr_true, alpha),
        "rigid body + drive": _low_pass(at_truth + fr_true - ext - drive, alpha) + shift,
        "state lag": _low_pass(link - at_truth, alpha),
        "output filter": _low_pass(ext, alpha) - ext,
    }
    tau_est = np.array([s["last_tau_ext"] for s in st])
    weights = np.array([s["joint_weight"] for s in st])
    forces = {name: np.array([_fit(est, jac[k], weights[k], t[k]) for k in range(N)])
              for name, t in tau_parts.items()}
    fit_true = np.array([_fit(est, jac[k], weights[k], ext[k]) for k in range(N)])
    forces["force fit"] = fit_true - applied
    f_est = np.array([s["last_wrench"][:3] for s in st])
    error = f_est - applied
    # the low-passes here start from 0, the estimator's after its set-up's updates: compare
    # once that start has decayed (1 s: (1 - α)^1000 < 1e-8 at 3 Hz and 1 ms)
    settled = slice(round(1.0 / est.config.dt), None)
    closure = float(np.abs(sum(forces.values()) - error)[settled].max())
    if np.abs(sum(tau_parts.values()) + ext - tau_est)[settled].max() > 1e-6 or closure > 1e-6:
        raise RuntimeError("the parts do not add up to the estimate")
    moving = _commanded_speed(log, f_est) >= moving_speed
    moving[:settled.start] = False     # the parts close from then on

    def rms(x: Array) -> float:
        return float(np.sqrt(np.mean(np.sum(x[moving] ** 2, axis=1)))) if moving.any() else 0.0

    fric = tau_parts["friction"]
    slow = np.abs(np.array(samples.state[:N])[:, 1]) < SLOW_JOINT

    def fit_at(tau: Array, at: NDArray[np.bool_] = moving) -> Array:
        """``tau``'s force through the estimator's fit at the samples ``at`` (0 elsewhere)."""
        out = np.zeros((N, 3))
        for k in np.flatnonzero(at):
            out[k] = _fit(est, jac[k], weights[k], tau[k])
        return out

    joint = []
    for j in range(robot.n):
        only = np.zeros_like(fric)
        only[:, j] = fric[:, j]
        joint.append(rms(fit_at(only)))
    window = release_windows(applied, cfg.dt)
    floor = sensing_floor(np.array(samples.sensing[:N]), ext, alpha, cfg.dt,
                          lambda tau: fit_at(tau, moving | window), moving, window)
    if abs(floor[LAG_ALONE].in_motion - rms(forces["output filter"])) > 1e-9:
        raise RuntimeError("the floor's filter is not the estimator's")
    return Budget(total=rms(error), part={k: rms(v) for k, v in forces.items()},
                  without={k: rms(error - v) for k, v in forces.items()},
                  moving=int(moving.sum()), closure=closure,
                  friction_slow=rms(fit_at(np.where(slow, fric, 0.0))),
                  friction_sliding=rms(fit_at(np.where(slow, 0.0, fric))),
                  friction_joint=tuple(joint), floor=floor)


@dataclass(frozen=True)
class Floor:
    """The current sensing's floor with one output filter [N]: the RMS in motion, and the
    largest phantom (|f̂| within ``PHANTOM_WINDOW_S`` after a release, as
    ``phantom_forces``)."""

    in_motion: float
    phantom: float


def release_windows(applied: Array, dt: float, window_s: float = PHANTOM_WINDOW_S
                    ) -> NDArray[np.bool_]:
    """The samples within ``window_s`` after each release (the first sample without an
    applied force after one with it), up to the next push, as ``phantom_forces`` takes them.

    Args:
        applied: The applied force per sample [N], shape (N, 3).
        dt: Sample period [s].
        window_s: Window after each release [s].
    """
    window = np.zeros(applied.shape[0], dtype=bool)
    for start, stop in hands_off_intervals(applied):
        if start > 0:   # a release follows a push
            window[start:min(stop, start + round(window_s / dt))] = True
    return window


def sensing_floor(sensing: Array, ext: Array, alpha: float, dt: float,
                  force_at: Callable[[Array], Array], moving: NDArray[np.bool_],
                  window: NDArray[np.bool_]) -> dict[str, Floor]:
    """The current sensing's floor (module docstring) per output filter.

    Args:
        sensing: The current sensor's error per sample [N·m], shape (N, n).
        ext: True τ_ext per sample [N·m], shape (N, n).
        alpha: The estimator's low-pass coefficient.
        dt: Sample period [s].
        force_at: A joint torque per sample [N·m], shape (N, n) → its force through the
            estimator's fit [N], shape (N, 3), at least where ``moving`` or ``window``.
        moving: The samples in motion, shape (N,).
        window: The samples after a release (:func:`release_windows`), shape (N,).

    Returns:
        Filter name → the floor; :data:`OWN_FILTER` is the estimator's filter, and
        :data:`LAG_ALONE` that filter's lag without the sensor's error.
    """
    def floor(error: Array) -> Floor:
        f = force_at(error)     # the estimate minus the applied force (0 after a release)
        in_motion = float(np.sqrt(np.mean(np.sum(f[moving] ** 2, axis=1))))
        phantom = float(np.linalg.norm(f[window], axis=1).max()) if window.any() else 0.0
        return Floor(in_motion, phantom)

    out = {OWN_FILTER: floor(_low_pass(sensing + ext, alpha) - ext),
           LAG_ALONE: floor(_low_pass(ext, alpha) - ext)}
    for name, (b, a) in _floor_filters(dt).items():
        out[name] = floor(scipy.signal.lfilter(b, a, sensing + ext, axis=0) - ext)
    return out


def run(robot: Robot, seed: int, operator: str, plant: str, cache: Path,
        hand_release: bool = False) -> Budget:
    """Calibrate instance ``seed`` (cached), run one session and split its error.

    ``operator`` is a scripted operator's name, or ``random:K`` for the ``random`` operator
    with operator seed K (``run_on.py``'s sessions); ``hand_release``: with the stop after
    letting go, as ``run_on.py``."""
    params = calibrated(robot, seed, plant, cache)
    samples = Samples()
    probes: list[BudgetProbe] = []

    def wrap(d: Driver) -> Driver:
        probes.append(BudgetProbe(d, samples))
        return probes[-1]

    def inspect(parts: LoopParts) -> None:
        probes[-1].estimator = parts.estimator

    name, _, op_seed = operator.partition(":")
    # guiding.py's settings: the push and the random pushes with the lighter mass, the paths
    # (diagonal, seam) with the defaults
    guiding = LoopConfig().guiding if name in PATHS else light_guiding()
    if hand_release:
        guiding = replace(guiding, hand_release=HandReleaseConfig(enabled=True))
    config = SimSessionConfig(operator=name, seed=seed, plant=plant,
                              operator_seed=int(op_seed) if op_seed else None,
                              loop=LoopConfig(guiding=guiding))
    session = run_sim_session(robot, params, config, wrap_driver=wrap, inspect_loop=inspect)
    estimator = probes[-1].estimator
    assert estimator is not None   # set by inspect_loop before the run
    return budget(robot, samples, estimator, session.result.log)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--instances", default="3,4,5")
    ap.add_argument("--operators", default="push-x,seam")
    ap.add_argument("--plant", choices=PLANT_NAMES, default=PLANT_NAMES[0])
    ap.add_argument("--hand-release", action="store_true",
                    help="the stop after letting go (run_on.py's setting)")
    ap.add_argument("--cache", type=Path,
                    default=Path(tempfile.gettempdir()) / "leadthrough-run-on")
    args = ap.parse_args()
    robot = load_robot("er20")
    head = " | ".join(f"{p:>18}" for p in PARTS)
    print(f"Force error in motion [N RMS] and its parts; '(w/o)': the total without the part "
          f"(plant {args.plant}; goal 5 N)\n{'instance, session':<20} {'total':>6} | {head}")
    budgets = []
    for seed in (int(s) for s in args.instances.split(",")):
        for op in args.operators.split(","):
            b = run(robot, seed, op, args.plant, args.cache, args.hand_release)
            budgets.append((f"{seed}, {op}", b))
            if not b.moving:
                print(f"{f'{seed}, {op}':<20} {'—':>6} | the TCP never reached "
                      f"{MOTION_SPEED} m/s", flush=True)
                continue
            cells = " | ".join(f"{b.part[p]:6.1f} (w/o {b.without[p]:5.1f})" for p in PARTS)
            print(f"{f'{seed}, {op}':<20} {b.total:6.1f} | {cells}   "
                  f"[{b.moving} samples; parts add up to {b.closure:.1e} N]", flush=True)
    print(f"\nThe friction part [N RMS in motion]: from joints slower than {SLOW_JOINT} rad/s "
          "at the sample, from the others, and from each joint alone")
    for label, b in budgets:
        if b.moving:
            per = " ".join(f"{v:5.1f}" for v in b.friction_joint)
            print(f"{label:<20} slow {b.friction_slow:5.1f}  sliding {b.friction_sliding:5.1f}"
                  f"  joints 1-{robot.n}: {per}")
    print("\nThe current sensing's floor [N]: the error with a perfect model, the current "
          "sensor's error through the output filter plus the filter's lag; RMS in motion and "
          f"the largest phantom after a release, with the estimator's filter and over "
          f"{len(_floor_filters(1e-3))} filters (goals 5 N and δ = 15 N)")
    for label, b in budgets:
        if b.moving:
            own, lag = b.floor[OWN_FILTER], b.floor[LAG_ALONE]
            others = {k: v for k, v in b.floor.items() if k not in (OWN_FILTER, LAG_ALONE)}
            motion = min(others, key=lambda k: others[k].in_motion)
            phantom = min(others, key=lambda k: others[k].phantom)
            both = [k for k, v in others.items() if v.in_motion <= 5.0 and v.phantom <= 15.0]
            print(f"{label:<20} the estimator's {own.in_motion:5.1f} / {own.phantom:5.1f} "
                  f"(its lag alone {lag.in_motion:4.1f} / {lag.phantom:4.1f})   "
                  f"smallest in motion {others[motion].in_motion:5.1f} / "
                  f"{others[motion].phantom:5.1f} ({motion})   smallest phantom "
                  f"{others[phantom].in_motion:5.1f} / {others[phantom].phantom:5.1f} "
                  f"({phantom})   both goals: {', '.join(both) or 'none'}")


if __name__ == "__main__":
    main()
