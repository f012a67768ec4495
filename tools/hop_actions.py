"""How a sub-policy acts on hop episodes: action shares and turn reversals, beside its success.

``python tools/hop_actions.py [--policy-dir DIR] [--agent pure|observable|oracle] [--every 9] [--limit 30]``

Runs the sub-policy (the shipped one, or the checkpoints in ``--policy-dir``) or a teacher on every
``--every``-th one-door test hop episode of roomnav-v2 (up to ``--limit``), 60 steps each, and
prints its success, how often it entered the target room, the share of each action, and how many
of its consecutive turns reversed direction (left then right, or right then left). A learner that
cannot tell which way to go dithers: it reverses about half of its turns, a teacher a few percent.
Every episode's action sampler is seeded from its index, so two runs print the same numbers.
"""

from __future__ import annotations

import argparse
import collections
import sys

from leaps_mj.environment import episodes as episodes_lib
from leaps_mj.environment import roomnav
from leaps_mj.environment.expert import GeodesicExpert
from leaps_mj.environment.observable_expert import ObservableExpert
from leaps_mj.learning import policies
from leaps_mj.world import rooms

LEFT_TURNS = {rooms.ACTION_NAMES.index(n) for n in ("left_rotate", "small_left_rotate")}
RIGHT_TURNS = {rooms.ACTION_NAMES.index(n) for n in ("right_rotate", "small_right_rotate")}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--policy-dir", default=None, help="sub-policy checkpoints (default: the shipped ones)")
    parser.add_argument("--agent", choices=("pure", "observable", "oracle"), default="pure")
    parser.add_argument("--greedy", action="store_true", help="most likely action instead of a sample")
    parser.add_argument("--dataset", default="roomnav-v2")
    parser.add_argument("--every", type=int, default=9, help="take every N-th one-door test hop episode")
    parser.add_argument("--limit", type=int, default=30, help="at most this many episodes")
    args = parser.parse_args(argv)
    if args.every < 1 or args.limit < 1:
        parser.error(f"--every {args.every}, --limit {args.limit}: expected positive integers")
    specs = [s for s in episodes_lib.load_split(args.dataset, "test", "hops") if s.plan_length == 1]
    specs = specs[::args.every][:args.limit]
    env = roomnav.load(args.dataset, "test", horizon=60, reward="sparse")
    if args.agent == "pure":
        policy = (policies.LearnedSubPolicy(args.policy_dir, policies.folder_targets(args.policy_dir),
                                            greedy=args.greedy)
                  if args.policy_dir else policies.load_default(greedy=args.greedy))
    else:
        policy = (ObservableExpert if args.agent == "observable" else GeodesicExpert)(env, seed=0)
    actions, success, entered, turns, reversals = collections.Counter(), 0, 0, 0, 0
    for i, spec in enumerate(specs):
        ts = env.reset_to(spec)
        if args.agent == "pure":
            policy.seed(i)
            policy.reset(spec.target)
        previous, inside = None, False
        while not ts.last():
            action = policy.act(ts)
            actions[action] += 1
            if previous is not None and {previous, action} <= LEFT_TURNS | RIGHT_TURNS:
                turns += 1
                reversals += (previous in LEFT_TURNS) != (action in LEFT_TURNS)
            previous = action
            ts = env.step(action)
            inside |= env.task.in_target
        success += ts.discount == 0.0
        entered += inside
    env.close()
    total = sum(actions.values())
    print(f"{len(specs)} one-door hop episodes ({args.dataset} test, every {args.every}th), 60 steps: "
          f"success {success}, entered the target room {entered}; turn reversals {reversals} of {turns} "
          f"consecutive turns ({100 * reversals / max(turns, 1):.0f} %)")
    print("action shares: " + ", ".join(f"{rooms.ACTION_NAMES[a]} {c / total:.2f}" for a, c in sorted(actions.items())))
    return 0


if __name__ == "__main__":
    sys.exit(main())
