"""Records: episodes written to MCAP with Foxglove schemas, and read back.

The recorder (:mod:`recorder`: images, poses, the house scene, bits, actions,
the belief graph and plan) and replay (:mod:`replay`: summaries, top-down
trajectories, GIF/MP4). Imports only :mod:`leaps_mj.world`; any ``dm_env``
loop can be recorded.
"""
