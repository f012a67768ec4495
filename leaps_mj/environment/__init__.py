"""Environment: RoomNav as a ``dm_env`` task over the houses of :mod:`leaps_mj.world`.

The physics and the RoomNav task (:mod:`roomnav`: actions, observations,
reward, the "see" success test, ``load``), off-screen rendering
(:mod:`render`) over batched static meshes (:mod:`batching`), fixed
evaluation episodes and the loop that runs an agent on one
(:mod:`episodes`), N environments in worker processes (:mod:`vector`), the
gymnasium adapter (:mod:`gym_adapter`) and the geodesic expert
(:mod:`expert`). Imports only :mod:`leaps_mj.world`.
"""
