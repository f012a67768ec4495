"""The gymnasium id's module: ``gymnasium.make("leaps_mj.gym_adapter:leaps_mj/RoomNav-v1")``.

Importing it registers the id (:mod:`leaps_mj.environment.gym_adapter`); it
stays at the package top because the id string users type names it.
"""

from leaps_mj.environment.gym_adapter import ENV_ID, make

__all__ = ["ENV_ID", "make"]
