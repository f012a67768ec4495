"""The gymnasium id's module: ``gymnasium.make("leaps_mj.gym_adapter:leaps_mj/RoomNav-v1")``.

Importing it registers the id (:mod:`leaps_mj.environment.gym_adapter`); it
stays at the package top because the id string users type names it.
"""

from leaps_mj.environment.gym_adapter import DEPTH_SCALE, ENV_ID, RoomNavGym, make, make_vec

__all__ = ["DEPTH_SCALE", "ENV_ID", "RoomNavGym", "make", "make_vec"]
