"""The prior trainer's house explorations on Ray actors.

``python -m leaps_mj.train prior ... --backend ray [--ray-address ADDR] [--num-workers N]``

Each actor (a plain Ray Core actor reserving one CPU,
:func:`leaps_mj.learning.ray_rollouts.actor_class`) holds one blind
environment over the split (the trainer's
:class:`~leaps_mj.learning.train_prior.HouseExplorer`). The remaining houses
are explored in rounds of one house per actor, in the split's order, and
their counts come back in that order, so the trainer pools and checkpoints
them house by house exactly as with worker processes. A house's runs are
seeded by the house alone (:func:`leaps_mj.learning.train_prior.house_seed`):
the counts do not depend on the backend or on which actor explored it.

**A lost actor** (its process or node died, ``ray.kill``) is replaced by a
fresh one, which explores its house of the round again, with the same
seeds, so nothing is lost or counted twice. Only an actor lost more than
``max_retries`` times in one round, or one that fails to start, stops the
run; the checkpoint (after every house) is the driver's, so a run may
resume on either backend.

This module does not import :mod:`leaps_mj.learning.train_prior` (which
imports it when the backend is chosen): the trainer hands it its explorer class.
"""

from __future__ import annotations

from typing import Iterator, Sequence

import numpy as np

from leaps_mj.learning import ray_rollouts

#: Seconds the driver waits for one actor's house (its first includes the actor's start-up).
HOUSE_TIMEOUT_S = 1800.0


class RayExplorers(ray_rollouts.ActorGroup):
    """Ray actors exploring houses one per round, results in the split's order.

    Args:
      explorer_cls: The plain class an actor runs (``HouseExplorer``: built from
        the config, ``explore(house_ids)`` returning one ``(id, positives, trials)`` per house).
      config: The run's ``PriorConfig``.
      houses: How many houses this session explores (bounds the number of actors).
      workers: Actors (None: one per cluster CPU, at most ``houses``).
      address: The Ray cluster's address (None: a local instance, or the one already initialised).
      max_retries: How many times one actor may be lost in one round.
      timeout_s: Seconds to wait for one actor's house (None: :data:`HOUSE_TIMEOUT_S`, read then).
    """

    noun = "explorer actor"

    def __init__(self, explorer_cls, config, houses: int, workers: int | None = None, address: str | None = None,
                 max_retries: int = 3, timeout_s: float | None = None):
        super().__init__(explorer_cls, houses, workers, address, max_retries, timeout_s or HOUSE_TIMEOUT_S)
        self._config = config

    def _start(self, actor: int):
        return self._remote.remote(self._config)

    def explore(self, house_ids: Sequence[str]) -> Iterator[tuple[str, np.ndarray, np.ndarray]]:
        """``(house id, positives, trials)`` of every house, in order, one round of actors at a time.

        Raises:
          RuntimeError: if an actor failed to start or was lost more than ``max_retries`` times.
          TimeoutError: if an actor returned nothing within ``timeout_s``.
        """
        house_ids = list(house_ids)
        for first in range(0, len(house_ids), len(self.actors)):
            chunk = house_ids[first:first + len(self.actors)]
            rounds = self.gather(lambda a, actor: actor.explore.remote(chunk[a:a + 1]), "house counts",
                                 f"houses {first}-{first + len(chunk) - 1}")
            for counts in rounds:
                yield from counts
