"""N RoomNav environments in worker processes, stepped together.

Environments are spread over ``num_workers`` processes (by default one per
core), each worker holding several and stepping them all on one message, so
the process round trip is paid once per worker, not once per environment.
Frames (segmentation, depth, RGB: every array observation of at least
:data:`SHARED_MIN_BYTES`) travel through shared memory, written by the
worker into its environments' slots and copied out by the parent; only the
small fields (bits, reward, step type) are pickled. Environment ``i`` gets
seed ``seed + i`` and ``worker_kwargs[i]`` whatever the grouping, so results
do not depend on ``num_workers``.

The API mirrors dm_env with lists: ``reset() -> [TimeStep]``,
``step(actions) -> [TimeStep]``; as in dm_env, a step after a LAST time step
starts a new episode and returns FIRST, so training loops need no special
casing. Errors in an environment (a bad action) come back as the same
exception type, naming the environment, and the worker stays usable.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import traceback
from multiprocessing import shared_memory

import dm_env
import numpy as np

#: Array observations at least this large go through shared memory.
SHARED_MIN_BYTES = 1024


def _shared_keys(obs_spec) -> dict[str, tuple[tuple[int, ...], np.dtype]]:
    """Observation keys sent through shared memory, with their shape and dtype."""
    out = {}
    for key, spec in obs_spec.items():
        if hasattr(spec, "shape") and int(np.prod(spec.shape)) * np.dtype(spec.dtype).itemsize >= SHARED_MIN_BYTES:
            out[key] = (tuple(spec.shape), np.dtype(spec.dtype))
    return out


def _attach(names: dict[str, str], layout, num_envs: int):
    """Worker side: numpy views of the shared blocks (the parent owns and unlinks them)."""
    blocks, views = [], {}
    for key, name in names.items():
        block = shared_memory.SharedMemory(name=name)
        shape, dtype = layout[key]
        blocks.append(block)
        views[key] = np.ndarray((num_envs, *shape), dtype, buffer=block.buf)
    return blocks, views


def _worker(conn, make_env, env_kwargs, seeds, slots):
    if make_env is None:
        from leaps_mj.environment import roomnav

        make_env = roomnav.load
    envs = [make_env(seed=seed, **kwargs) for seed, kwargs in zip(seeds, env_kwargs)]
    blocks, views = [], {}

    def pack(slot, ts):
        """Writes the frames of a time step into the environment's shared slot; returns the rest."""
        small = {}
        for key, value in ts.observation.items():
            if key in views:
                views[key][slot] = value
            else:
                small[key] = value
        return ts.step_type, ts.reward, ts.discount, small

    try:
        while True:
            cmd, args = conn.recv()
            if cmd == "close":
                conn.send(("ok", None))
                break
            if cmd == "attach":
                names, layout, total = args
                blocks, views = _attach(names, layout, total)
                conn.send(("ok", None))
                continue
            results = []
            for j, env in enumerate(envs):
                try:
                    if cmd == "step":
                        results.append(("ok", env.step(args[j])))
                    elif cmd == "reset":
                        results.append(("ok", env.reset()))
                    elif cmd == "reset_to":
                        results.append(("ok", env.reset_to(args[j])))
                    elif cmd == "episode":
                        results.append(("ok", env.episode))
                    elif cmd == "specs":
                        results.append(("ok", (env.observation_spec(), env.action_spec())))
                    else:
                        raise ValueError(f"unknown command {cmd!r}")
                except Exception as e:  # noqa: BLE001 - forwarded to the parent
                    results.append(("error", (type(e), str(e), traceback.format_exc())))
            if cmd in ("step", "reset", "reset_to") and views:
                results = [(s, pack(slot, v)) if s == "ok" else (s, v) for slot, (s, v) in zip(slots, results)]
            conn.send(("ok", results))
    except (EOFError, KeyboardInterrupt):
        pass
    finally:
        for env in envs:
            env.close()
        for block in blocks:
            block.close()
        conn.close()


def split(num_envs: int, num_workers: int) -> list[list[int]]:
    """Environment indices per worker: contiguous, sizes differing by at most one (also Ray's rollout actors')."""
    bounds = np.linspace(0, num_envs, num_workers + 1).round().astype(int)
    return [list(range(bounds[w], bounds[w + 1])) for w in range(num_workers)]


class VectorEnv:
    """``num_envs`` environments in ``num_workers`` processes.

    Args:
      num_envs: number of environments.
      seed: environment ``i`` gets seed ``seed + i``.
      start_method: multiprocessing start method ("spawn" is safe with GL).
      make_env: picklable callable ``(seed=..., **kwargs) -> environment``
        building each environment (e.g. a wrapper around
        :func:`leaps_mj.load`); None means :func:`leaps_mj.load`.
      worker_kwargs: optional list of ``num_envs`` dicts, environment ``i``'s
        own arguments (e.g. a shard of the houses), merged over ``env_kwargs``.
      num_workers: worker processes (default: one per core, at most ``num_envs``).
      **env_kwargs: passed to ``make_env`` (dataset, split, config).

    Raises:
      ValueError: for a bad ``num_envs``, ``num_workers`` or ``worker_kwargs`` length.
    """

    def __init__(self, num_envs: int, seed: int = 0, start_method: str = "spawn", make_env=None,
                 worker_kwargs=None, num_workers: int | None = None, **env_kwargs):
        if isinstance(num_envs, bool) or not isinstance(num_envs, int) or num_envs < 1:
            raise ValueError(f"num_envs {num_envs!r}: expected a positive integer")
        if num_workers is None:
            num_workers = min(num_envs, os.cpu_count() or 1)
        if isinstance(num_workers, bool) or not isinstance(num_workers, int) or not 1 <= num_workers <= num_envs:
            raise ValueError(f"num_workers {num_workers!r}: expected an integer in [1, num_envs={num_envs}]")
        if worker_kwargs is not None and len(worker_kwargs) != num_envs:
            raise ValueError(f"worker_kwargs has {len(worker_kwargs)} entries for {num_envs} environments")
        ctx = mp.get_context(start_method)
        self.num_envs, self.num_workers = num_envs, num_workers
        self._groups = split(num_envs, num_workers)
        self._conns, self._procs, self._blocks, self._views = [], [], [], {}
        self._closed = False
        for group in self._groups:
            parent, child = ctx.Pipe()
            kwargs = [{**env_kwargs, **(worker_kwargs[i] if worker_kwargs is not None else {})} for i in group]
            p = ctx.Process(target=_worker, args=(child, make_env, kwargs, [seed + i for i in group], group),
                            daemon=True)
            p.start()
            child.close()
            self._conns.append(parent)
            self._procs.append(p)
        self._obs_spec, self._act_spec = self._broadcast("specs", None)[0]
        self._share(_shared_keys(self._obs_spec))

    def _share(self, layout) -> None:
        """Creates the shared frame blocks and has every worker attach them."""
        names = {}
        for key, (shape, dtype) in layout.items():
            block = shared_memory.SharedMemory(create=True, size=self.num_envs * int(np.prod(shape)) * dtype.itemsize)
            self._blocks.append(block)
            self._views[key] = np.ndarray((self.num_envs, *shape), dtype, buffer=block.buf)
            names[key] = block.name
        if names:
            for conn in self._conns:
                conn.send(("attach", (names, layout, self.num_envs)))
            for conn in self._conns:
                conn.recv()

    def _broadcast(self, cmd, args):
        """Sends ``cmd`` (with per-environment ``args``) to every worker; returns one result per environment."""
        for conn, group in zip(self._conns, self._groups):
            conn.send((cmd, None if args is None else [args[i] for i in group]))
        results, first_error = [None] * self.num_envs, None
        for conn, group in zip(self._conns, self._groups):
            _, replies = conn.recv()
            for i, (status, out) in zip(group, replies):
                if status == "error":
                    etype, msg, tb = out
                    error = etype(f"env {i}: {msg}") if etype in (ValueError, RuntimeError) else RuntimeError(
                        f"env {i} failed:\n{tb}")
                    first_error = first_error or error
                else:
                    results[i] = out
        if first_error is not None:
            raise first_error
        if cmd in ("step", "reset", "reset_to") and self._views:
            results = [self._timestep(i, packed) for i, packed in enumerate(results)]
        return results

    def _timestep(self, i: int, packed) -> dm_env.TimeStep:
        step_type, reward, discount, small = packed
        obs = {key: (self._views[key][i].copy() if key in self._views else small[key]) for key in self._obs_spec}
        obs.update((k, v) for k, v in small.items() if k not in obs)
        return dm_env.TimeStep(step_type, reward, discount, obs)

    def observation_spec(self):
        return self._obs_spec

    def action_spec(self):
        return self._act_spec

    def reset(self):
        """Resets every environment; returns their FIRST time steps."""
        return self._broadcast("reset", None)

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
        return self._broadcast("episode", None)

    def close(self):
        """Stops the workers and frees the shared memory (idempotent)."""
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
        self._views.clear()
        for block in self._blocks:
            block.close()
            block.unlink()
        self._blocks.clear()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def __del__(self):
        if hasattr(self, "_closed"):
            self.close()


def stack(timesteps, key: str) -> np.ndarray:
    """Stacks one observation field over a list of time steps."""
    return np.stack([ts.observation[key] for ts in timesteps])
