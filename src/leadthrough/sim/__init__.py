"""The simulated robot (MuJoCo plant, rich drive train, position servo, noisy sensors)."""

from leadthrough.sim.drivetrain import DriveTrainConfig, DriveTrainTruth
from leadthrough.sim.mujoco_model import Payload, build_mujoco_model
from leadthrough.sim.operator import ConstantWrench, Mark, NoOperator, Operator, ScriptedOperator
from leadthrough.sim.operator_scripts import OPERATOR_NAMES, make_operator
from leadthrough.sim.robot import Feedback, SimConfig, SimRobot, SimTruth
from leadthrough.sim.run import SimLog, SimTruthLog, hold, run_trajectory
from leadthrough.sim.sensors import SensorConfig

__all__ = [
    "OPERATOR_NAMES",
    "ConstantWrench",
    "DriveTrainConfig",
    "DriveTrainTruth",
    "Feedback",
    "Mark",
    "NoOperator",
    "Operator",
    "Payload",
    "ScriptedOperator",
    "SensorConfig",
    "SimConfig",
    "SimLog",
    "SimRobot",
    "SimTruth",
    "SimTruthLog",
    "build_mujoco_model",
    "hold",
    "make_operator",
    "run_trajectory",
]
