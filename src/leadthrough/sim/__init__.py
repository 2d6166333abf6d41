"""The simulated robot (MuJoCo plant, rich drive train, position servo, noisy sensors), its
driver with fault injection, scripted operators, and guiding sessions on it."""

from leadthrough.sim.driver import InjectedFault, InjectedFaultKind, SimDriver
from leadthrough.sim.drivetrain import DriveTrainConfig, DriveTrainTruth
from leadthrough.sim.mujoco_model import Payload, build_mujoco_model
from leadthrough.sim.operator import ConstantWrench, Mark, NoOperator, Operator, ScriptedOperator
from leadthrough.sim.operator_scripts import OPERATOR_NAMES, make_operator
from leadthrough.sim.plant import PLANT_NAMES, PlantPreset
from leadthrough.sim.robot import SimConfig, SimRobot, SimTruth
from leadthrough.sim.run import SimLog, SimTruthLog, hold, run_trajectory
from leadthrough.sim.sensors import Feedback, SensorConfig
from leadthrough.sim.session import SimSession, SimSessionConfig, replay_session, run_sim_session

__all__ = [
    "OPERATOR_NAMES",
    "PLANT_NAMES",
    "ConstantWrench",
    "DriveTrainConfig",
    "DriveTrainTruth",
    "Feedback",
    "InjectedFault",
    "InjectedFaultKind",
    "Mark",
    "NoOperator",
    "Operator",
    "Payload",
    "PlantPreset",
    "ScriptedOperator",
    "SensorConfig",
    "SimConfig",
    "SimDriver",
    "SimLog",
    "SimRobot",
    "SimSession",
    "SimSessionConfig",
    "SimTruth",
    "SimTruthLog",
    "build_mujoco_model",
    "hold",
    "make_operator",
    "replay_session",
    "run_sim_session",
    "run_trajectory",
]
