"""Environment: RoomNav as a ``dm_env`` task over the houses of :mod:`leaps_mj.world`.

The physics and the RoomNav task (:mod:`roomnav`: actions, observations,
reward, the "see" success test, ``load``), off-screen rendering
(:mod:`render`) over batched static meshes (:mod:`batching`), fixed
evaluation episodes and the loop that runs an agent on one
(:mod:`episodes`), N environments in worker processes (:mod:`vector`), the
gymnasium adapter (:mod:`gym_adapter`), the geodesic expert
(:mod:`expert`), the observable expert that chooses only from what the agent
has seen (:mod:`observable_expert`) and how Ray workers are connected and started
(:mod:`ray_cluster`, for the Ray backends above). Imports only
:mod:`leaps_mj.world`.
"""
