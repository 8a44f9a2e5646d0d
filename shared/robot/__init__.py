"""PR2 model for planning and execution: torso + right arm kinematics, collision spheres, IK.

The robot is described by the repo's own URDF (``shared/data/robot/pr2.urdf``) and sphere file
(``shared/data/robot/pr2_spheres.toml``), read by :mod:`shared.robot.files`. pytorch-kinematics parses
the URDF, builds the chain and is the reference forward kinematics and the IK solver
(:mod:`shared.robot.ik`). The planner's hot path uses a fused serial-chain kernel
(:mod:`shared.robot.chain`) derived from pytorch-kinematics' parsed chain (fixed offsets folded, one
batched rotation per joint written as a two-column update) that is tested equal to
``forward_kinematics_tensor``; :mod:`shared.robot.spheres` attaches the collision spheres to its links.

Planned joints (D = 8, in this order): ``torso_lift_joint`` and the seven right-arm joints. The head,
the tucked left arm and the fingers are held at the sphere file's ``[posture]``; their spheres move
rigidly with their nearest planned ancestor link. The base is fixed in the world at
``base_transform`` (world-from-``base_footprint``).

Continuous joints (``r_forearm_roll_joint``, ``r_wrist_roll_joint``) have no URDF limits; this model
gives them the finite range ``CONTINUOUS_RANGE`` = [-pi, pi] (pytorch-kinematics would report (0, 0)).
"""

from .chain import CONTINUOUS_RANGE, JOINT_NAMES, ROOT_FRAME, TOOL_FRAME, ChainTables
from .files import RobotModelError, load_spheres
from .pr2 import PR2
from .spheres import SphereTables

__all__ = ["PR2", "RobotModelError", "JOINT_NAMES", "CONTINUOUS_RANGE", "TOOL_FRAME", "ROOT_FRAME",
           "load_spheres", "ChainTables", "SphereTables"]
