"""N RoomNav environments in worker processes, stepped together.

Each worker owns one :func:`leaps_mj.environment.roomnav.load` environment (its own GL
context, house cache and RNG); the parent sends all actions, then gathers all
time steps, so rendering runs on every core. The API mirrors dm_env with lists:
``reset() -> [TimeStep]``, ``step(actions) -> [TimeStep]``; as in dm_env, a
step after a LAST time step starts a new episode and returns FIRST, so
training loops need no special casing. Errors in a worker (a bad action)
come back as the same exception type, naming the worker, and the worker stays
usable.
"""

from __future__ import annotations

import multiprocessing as mp
import traceback

import numpy as np


def _worker(conn, make_env, env_kwargs, seed):
    if make_env is None:
        from leaps_mj.environment import roomnav

        make_env = roomnav.load
    env = make_env(seed=seed, **env_kwargs)
    try:
        while True:
            cmd, arg = conn.recv()
            try:
                if cmd == "step":
                    out = env.step(arg)
                elif cmd == "reset":
                    out = env.reset()
                elif cmd == "reset_to":
                    out = env.reset_to(arg)
                elif cmd == "episode":
                    out = env.episode
                elif cmd == "specs":
                    out = (env.observation_spec(), env.action_spec())
                elif cmd == "close":
                    conn.send(("ok", None))
                    break
                else:
                    raise ValueError(f"unknown command {cmd!r}")
                conn.send(("ok", out))
            except Exception as e:  # noqa: BLE001 - forwarded to the parent
                conn.send(("error", (type(e), str(e), traceback.format_exc())))
    except (EOFError, KeyboardInterrupt):
        pass
    finally:
        env.close()
        conn.close()


class VectorEnv:
    """``num_envs`` environments, each in its own process.

    Args:
      num_envs: number of worker processes.
      seed: worker ``i`` gets seed ``seed + i``.
      start_method: multiprocessing start method ("spawn" is safe with GL).
      make_env: picklable callable ``(seed=..., **kwargs) -> environment``
        building each worker's environment (e.g. a wrapper around
        :func:`leaps_mj.load`); None means :func:`leaps_mj.load`.
      worker_kwargs: optional list of ``num_envs`` dicts, worker ``i``'s own
        arguments (e.g. a shard of the houses), merged over ``env_kwargs``.
      **env_kwargs: passed to ``make_env`` (dataset, split, config).
    """

    def __init__(self, num_envs: int, seed: int = 0, start_method: str = "spawn", make_env=None,
                 worker_kwargs=None, **env_kwargs):
        if not isinstance(num_envs, int) or num_envs < 1:
            raise ValueError(f"num_envs {num_envs!r}: expected a positive integer")
        if worker_kwargs is not None and len(worker_kwargs) != num_envs:
            raise ValueError(f"worker_kwargs has {len(worker_kwargs)} entries for {num_envs} workers")
        ctx = mp.get_context(start_method)
        self._conns, self._procs = [], []
        for i in range(num_envs):
            parent, child = ctx.Pipe()
            kwargs = {**env_kwargs, **(worker_kwargs[i] if worker_kwargs is not None else {})}
            p = ctx.Process(target=_worker, args=(child, make_env, kwargs, seed + i), daemon=True)
            p.start()
            child.close()
            self._conns.append(parent)
            self._procs.append(p)
        self.num_envs = num_envs
        self._closed = False
        self._obs_spec, self._act_spec = self._call(0, "specs")

    def _recv(self, i):
        status, out = self._conns[i].recv()
        if status == "error":
            etype, msg, tb = out
            raise etype(f"worker {i}: {msg}") if etype in (ValueError, RuntimeError) else RuntimeError(
                f"worker {i} failed:\n{tb}")
        return out

    def _call(self, i, cmd, arg=None):
        self._conns[i].send((cmd, arg))
        return self._recv(i)

    def _broadcast(self, cmd, args):
        for conn, arg in zip(self._conns, args):
            conn.send((cmd, arg))
        results, first_error = [], None
        for i in range(self.num_envs):
            try:
                results.append(self._recv(i))
            except Exception as e:  # noqa: BLE001 - drain every pipe before raising
                results.append(None)
                first_error = first_error or e
        if first_error is not None:
            raise first_error
        return results

    def observation_spec(self):
        return self._obs_spec

    def action_spec(self):
        return self._act_spec

    def reset(self):
        """Resets every environment; returns their FIRST time steps."""
        return self._broadcast("reset", [None] * self.num_envs)

    def reset_to(self, specs):
        """Starts the given episode spec in each environment."""
        return self._broadcast("reset_to", list(specs))

    def step(self, actions):
        """Steps environment ``i`` with ``actions[i]``."""
        actions = list(np.asarray(actions).reshape(-1)) if not isinstance(actions, list) else actions
        if len(actions) != self.num_envs:
            raise ValueError(f"got {len(actions)} actions for {self.num_envs} environments")
        return self._broadcast("step", actions)

    def episodes(self):
        """The current episode spec of every environment."""
        return self._broadcast("episode", [None] * self.num_envs)

    def close(self):
        """Stops the workers (idempotent)."""
        if self._closed:
            return
        self._closed = True
        for conn in self._conns:
            try:
                conn.send(("close", None))
                conn.recv()
            except (BrokenPipeError, EOFError, OSError):
                pass
            conn.close()
        for p in self._procs:
            p.join(timeout=5)
            if p.is_alive():
                p.terminate()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def __del__(self):
        self.close()


def stack(timesteps, key: str) -> np.ndarray:
    """Stacks one observation field over a list of time steps."""
    return np.stack([ts.observation[key] for ts in timesteps])
