"""Ready-made systems: the paper's robot arm."""

from etobs.examples.robot_arm import (
    L_PAPER,
    X0_PAPER,
    random_initial_states,
    robot_arm,
    robot_arm_network,
)

__all__ = ["L_PAPER", "X0_PAPER", "random_initial_states", "robot_arm", "robot_arm_network"]
