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
``step(actions) -> [TimeStep]``, every worker stepped in lock-step; for throughput
without the lock-step, ``async_reset()``, then ``recv() -> (env_ids, [TimeStep])`` from
whichever worker finished first and ``send(env_ids, actions)`` back to it (EnvPool's
asynchronous mode, at the granularity of a worker); as in dm_env, a step after a LAST time step
starts a new episode and returns FIRST, so training loops need no special
casing. Errors in an environment (a bad action) come back as the same
exception type, naming the environment, and the worker stays usable.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import traceback
from multiprocessing import connection, shared_memory

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


def _worker(conn, make_env, env_kwargs, seeds, slots, cpu):
    if cpu is not None:
        os.sched_setaffinity(0, {cpu})
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
      pin: whether worker ``w`` is bound to the ``w``-th CPU this process may run on (round robin).
        A worker that blocks on its pipe every step is otherwise moved between cores by the scheduler
        and loses its caches; on the 2-core machine pinning made 2 workers 1.05-1.26x faster
        (``benchmarks/env_throughput.py``). Leave it off where other pinned work shares the CPUs.
      **env_kwargs: passed to ``make_env`` (dataset, split, config).

    Raises:
      ValueError: for a bad ``num_envs``, ``num_workers`` or ``worker_kwargs`` length.
    """

    def __init__(self, num_envs: int, seed: int = 0, start_method: str = "spawn", make_env=None,
                 worker_kwargs=None, num_workers: int | None = None, pin: bool = False, **env_kwargs):
        if isinstance(num_envs, bool) or not isinstance(num_envs, int) or num_envs < 1:
            raise ValueError(f"num_envs {num_envs!r}: expected a positive integer")
        if num_workers is None:
            num_workers = min(num_envs, os.cpu_count() or 1)
        if isinstance(num_workers, bool) or not isinstance(num_workers, int) or not 1 <= num_workers <= num_envs:
            raise ValueError(f"num_workers {num_workers!r}: expected an integer in [1, num_envs={num_envs}]")
        if worker_kwargs is not None and len(worker_kwargs) != num_envs:
            raise ValueError(f"worker_kwargs has {len(worker_kwargs)} entries for {num_envs} environments")
        ctx = mp.get_context(start_method)
        cpus = sorted(os.sched_getaffinity(0))
        self.num_envs, self.num_workers = num_envs, num_workers
        self._groups = split(num_envs, num_workers)
        self._conns, self._procs, self._blocks, self._views = [], [], [], {}
        self._pending: dict[int, str] = {}  # worker -> the command it is running (asynchronous use)
        self._closed = False
        for w, group in enumerate(self._groups):
            parent, child = ctx.Pipe()
            kwargs = [{**env_kwargs, **(worker_kwargs[i] if worker_kwargs is not None else {})} for i in group]
            p = ctx.Process(target=_worker, args=(child, make_env, kwargs, [seed + i for i in group], group,
                                                       cpus[w % len(cpus)] if pin else None),
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

    def _send(self, cmd, args, workers) -> None:
        """Sends ``cmd`` to each of ``workers``, with their environments' slice of ``args`` (None: no arguments)."""
        for w in workers:
            if w in self._pending:
                raise RuntimeError(f"worker {w} (environments {self._groups[w]}) is still stepping: recv() first")
            self._conns[w].send((cmd, None if args is None else [args[i] for i in self._groups[w]]))
            self._pending[w] = cmd

    def _receive(self, w: int):
        """Worker ``w``'s reply to its pending command: one result per environment of its group.

        Raises:
          ValueError / RuntimeError: an environment's error, naming the environment.
        """
        cmd = self._pending.pop(w)
        _, replies = self._conns[w].recv()
        results, first_error = [], None
        for i, (status, out) in zip(self._groups[w], replies):
            if status == "error":
                etype, msg, tb = out
                error = etype(f"env {i}: {msg}") if etype in (ValueError, RuntimeError) else RuntimeError(
                    f"env {i} failed:\n{tb}")
                first_error = first_error or error
            elif cmd in ("step", "reset", "reset_to") and self._views:
                out = self._timestep(i, out)
            results.append(out)
        if first_error is not None:
            raise first_error
        return results

    def _broadcast(self, cmd, args):
        """Sends ``cmd`` (with per-environment ``args``) to every worker; returns one result per environment."""
        if self._pending:
            raise RuntimeError(f"workers {sorted(self._pending)} are still stepping: recv() their results first")
        self._send(cmd, args, range(self.num_workers))
        results, first_error = [], None
        for w in range(self.num_workers):
            try:
                results.extend(self._receive(w))
            except (ValueError, RuntimeError) as error:  # every worker's reply is read before raising
                first_error = first_error or error
        if first_error is not None:
            raise first_error
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

    def async_reset(self) -> None:
        """Starts resetting every environment without waiting; collect the FIRST time steps with :meth:`recv`."""
        self._send("reset", None, range(self.num_workers))

    def recv(self) -> tuple[list[int], list[dm_env.TimeStep]]:
        """Waits for the first worker to finish its pending reset or step (asynchronous use).

        Returns:
          That worker's environment indices and their time steps; step those environments next with
          :meth:`send`. Until then the worker idles while the others go on, so no environment waits for
          the slowest one (the lock-step of :meth:`step`). The order in which workers finish depends on
          timing, so a training loop that pools their results is not reproducible step for step, while
          each environment's own trajectory, given its actions, is.

        Raises:
          RuntimeError: if no worker has a pending command.
        """
        if not self._pending:
            raise RuntimeError("recv() with nothing pending: call async_reset() or send() first")
        conns = {self._conns[w]: w for w in self._pending}
        w = conns[connection.wait(list(conns))[0]]
        return list(self._groups[w]), self._receive(w)

    def send(self, env_ids, actions) -> None:
        """Starts stepping one worker's environments (the indices :meth:`recv` returned) without waiting.

        Raises:
          ValueError: if ``env_ids`` are not exactly one worker's environments, or the actions do not match them.
        """
        env_ids = [int(i) for i in env_ids]
        actions = list(np.asarray(actions).reshape(-1)) if not isinstance(actions, list) else actions
        if env_ids not in self._groups:
            raise ValueError(f"env_ids {env_ids}: expected one worker's environments, one of {self._groups}")
        if len(actions) != len(env_ids):
            raise ValueError(f"got {len(actions)} actions for environments {env_ids}")
        w = self._groups.index(env_ids)
        by_env = dict(zip(env_ids, actions))
        self._send("step", by_env, [w])

    def episodes(self):
        """The current episode spec of every environment."""
        return self._broadcast("episode", None)

    def close(self):
        """Stops the workers and frees the shared memory (idempotent)."""
        if self._closed:
            return
        self._closed = True
        for w, conn in enumerate(self._conns):
            try:
                if self._pending.pop(w, None) is not None:
                    conn.recv()  # the reply to an asynchronous step nobody collected
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
