"""Case study of one LEAPS episode, like the paper's Fig. 3.

``python -m leaps_mj.evaluation.casestudy --episode K --split test --out FILE.png``

Runs the LEAPS agent on fixed episode K (with the same agent seed as
:mod:`leaps_mj.evaluate`, so it is the evaluation's run of that episode) and
draws, on the left, the house from above with the agent's trajectory split
into segments coloured by the sub-target it was pursuing, and, on the right,
the belief graph (posterior edge probabilities, planned path in red) after
each replanning that changed the plan.
"""

from __future__ import annotations

import argparse
import pathlib
import sys

import matplotlib.pyplot as plt
import numpy as np

from leaps_mj.environment import episodes as episodes_lib
from leaps_mj.environment import roomnav
from leaps_mj.evaluation import registry
from leaps_mj.planning import agents as agents_lib
from leaps_mj.planning import semantic
from leaps_mj.world import dataset as dataset_lib
from leaps_mj.world import rooms, topdown

#: Belief panels shown at most (the first and those whose plan changed).
MAX_PANELS = 6


def node_color(node: str):
    """A distinct colour per graph node (sub-target); tab10 without its red, which marks plans."""
    palette = [c for k, c in enumerate(plt.get_cmap("tab10").colors) if k != 3]
    return palette[rooms.room_index(node)]


class Trace:
    """An evaluation observer that keeps the agent's poses and sub-targets."""

    def begin(self, env, spec, agent):
        self.poses = [np.array(env.physics.agent_pose())]
        self.subtargets = []

    def step(self, timestep, action, info):
        self.poses.append(np.asarray(timestep.observation["pose"], dtype=float))
        self.subtargets.append(info["subtarget"])

    def end(self, result):
        self.result = result


def panels(history) -> list:
    """The replans worth a belief panel: the first, then each that changed the plan."""
    chosen = [h for k, h in enumerate(history) if k == 0 or h.plan != history[k - 1].plan]
    return chosen[:MAX_PANELS]


def figure(house, spec, trace: Trace, agent: agents_lib.LeapsAgent, title: str):
    """The case-study figure: trajectory by sub-target, and belief graphs after replanning."""
    shown = panels(agent.history)
    cols = 2
    rows = max(1, -(-len(shown) // cols))
    fig = plt.figure(figsize=(17, max(7.5, 3.3 * rows)), layout="constrained")
    grid = fig.add_gridspec(rows, 2 + cols, width_ratios=[1.6, 1.6, 1, 1])
    ax = fig.add_subplot(grid[:, :2])
    topdown.draw_house(ax, house, furniture_labels=False)
    xy = np.array([p[:2] for p in trace.poses])
    for node in dict.fromkeys(trace.subtargets):
        steps = [t for t, s in enumerate(trace.subtargets) if s == node]
        for t in steps:
            ax.plot(xy[t:t + 2, 0], xy[t:t + 2, 1], color=node_color(node), lw=2.2, zorder=5,
                    solid_capstyle="round")
        ax.plot([], [], color=node_color(node), lw=2.2, label=f"sub-target: {node.replace('_', ' ')}")
    ax.plot(*xy[0], marker="o", ms=9, color="black", zorder=6, label="start")
    ax.plot(*xy[-1], marker="*" if trace.result["success"] else "X", ms=13, color="black", zorder=6,
            label="success" if trace.result["success"] else "end (horizon)")
    ax.legend(loc="upper left", bbox_to_anchor=(0.0, -0.08), ncol=3, fontsize=8)
    ax.set_title(title, fontsize=10)
    model = agent.model
    for k, h in enumerate(shown):
        pax = fig.add_subplot(grid[k // cols, 2 + k % cols])
        snapshot = semantic.SemanticModel(model.prior, model.psi_obs0, model.psi_obs1, h.n_pos, h.n_neg)
        semantic.plot_belief(snapshot, pax, highlight_path=list(h.plan))
        pax.set_title(f"step {h.step} ({h.reason})\n" + " → ".join(n.replace("_", " ") for n in h.plan),
                      fontsize=8)
    return fig


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m leaps_mj.evaluation.casestudy", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--episode", type=int, required=True, help="index in the split's fixed episodes")
    p.add_argument("--split", default="test", choices=["valid", "test"])
    p.add_argument("--dataset", default=dataset_lib.CANONICAL)
    p.add_argument("--out", type=pathlib.Path, required=True, help="PNG file")
    p.add_argument("--horizon", type=int, default=1000)
    p.add_argument("--prior", default=None,
                   help=f"LEAPS prior (default: by sub-policy, {agents_lib.SUBPOLICY_PRIORS})")
    p.add_argument("--rule", choices=agents_lib.RULES, default="paper")
    p.add_argument("--replan-every", type=int, default=None,
                   help=f"LEAPS's N (default: by sub-policy, {agents_lib.SUBPOLICY_REPLAN_EVERY})")
    p.add_argument("--subpolicy", choices=["local", "learned"], default="local")
    p.add_argument("--seed", type=int, default=0, help="evaluation seed (agent seed of episode K derives from it)")
    args = p.parse_args(argv)
    args.prior, args.replan_every = agents_lib.subpolicy_defaults(args.subpolicy, args.prior, args.replan_every)
    try:
        specs = episodes_lib.load_split(args.dataset, args.split)
        if not 0 <= args.episode < len(specs):
            raise ValueError(f"--episode {args.episode}: expected an index in [0, {len(specs)})")
        spec = specs[args.episode]
        model = agents_lib.load_model(args.prior)
        env = roomnav.load(args.dataset, args.split, reward="sparse", horizon=args.horizon)
    except ValueError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    try:
        sub = None
        if args.subpolicy == "learned":
            from leaps_mj.learning import policies

            sub = policies.load_default()
        agent = registry.make_agent("leaps", env, subpolicy=sub, seed=episodes_lib.episode_seed(args.seed, args.episode),
                                      model=model, rule=args.rule, replan_every=args.replan_every)
        trace = Trace()
        result = episodes_lib.run_episode(env, agent, spec, args.horizon, observer=trace)
        house = env.task.house_model.house
    finally:
        env.close()
    outcome = f"success at step {result['success_step']}" if result["success"] else f"failed in {result['steps']} steps"
    title = (f"{args.split} episode {args.episode}: {spec.house}, target {spec.target.replace('_', ' ')}, "
             f"plan length {spec.plan_length}, {spec.geodesic:.1f} m — LEAPS ({args.rule} rule) {outcome}")
    topdown.save_figure(figure(house, spec, trace, agent, title), args.out, dpi=110)
    print(f"{title}\nreplans: {len(agent.history)}; wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
