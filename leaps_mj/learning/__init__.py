"""Learning: networks, the learned sub-policies and baselines, and their trainers.

Networks and checkpoints (:mod:`nets`), learned sub-policies μ(θ) and μ_s
(:mod:`policies`), the CNN room-type classifier's bits (:mod:`classifier`),
the learned baselines' agents (:mod:`baselines`: aug. μ_s and the LSTM
controller), and the trainers behind ``python -m leaps_mj.train``:
sub-policies (:mod:`train_policy`, its rollouts in :mod:`rollouts`, on Ray
actors in :mod:`ray_rollouts`), classifier (:mod:`train_classifier`),
controller (:mod:`train_controller`) and the prior (:mod:`train_prior`),
with their shared ``--backend`` options (:mod:`backend_options`).
Needs torch. Imports :mod:`leaps_mj.planning` and below.
"""
