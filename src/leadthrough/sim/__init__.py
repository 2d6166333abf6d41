"""The simulated robot (MuJoCo plant, rich drive train, position servo, noisy sensors)."""

from leadthrough.sim.drivetrain import DriveTrainConfig, DriveTrainTruth
from leadthrough.sim.mujoco_model import Payload, build_mujoco_model
from leadthrough.sim.operator import ConstantWrench, NoOperator, Operator
from leadthrough.sim.robot import Feedback, SimConfig, SimRobot, SimTruth
from leadthrough.sim.run import SimLog, SimTruthLog, hold, run_trajectory
from leadthrough.sim.sensors import SensorConfig

__all__ = [
    "ConstantWrench",
    "DriveTrainConfig",
    "DriveTrainTruth",
    "Feedback",
    "NoOperator",
    "Operator",
    "Payload",
    "SensorConfig",
    "SimConfig",
    "SimLog",
    "SimRobot",
    "SimTruth",
    "SimTruthLog",
    "build_mujoco_model",
    "hold",
    "run_trajectory",
]
