"""Studies beyond the paper on the obstacles its Discussion leaves to future work: several, moving and random-size
obstacles, agents that dodge them, and a one-step action delay. Seeds and budgets: see tools/experiment_registry.py.
"""

from tools.experiment_spec import Cross, Experiment, Run, register
from tools.registry_paper_tasks import AVOID_CURVES, AVOID_METRICS, PLUS_OBS, REACH_OBS

# The observations of the -moving3 presets (agents/presets.py: MOVING_OBSTACLES_3, the UR5e one with the plus
# parts), spelled here as the plus ones are; a test holds them equal.
_MOVING3_OBS = REACH_OBS + ("obstacle_pos", "obstacle_radius", "obstacle_vel", "link_obstacle_dist")
_MOVING3_PLUS_OBS = PLUS_OBS + tuple(p for p in _MOVING3_OBS if p not in PLUS_OBS)
_MOVING3_STATIC_OBS = tuple(p for p in _MOVING3_OBS if p != "obstacle_vel")
_STATIC = {"env.obstacle_motion": "static"}
# The UR5e preset's options before it took ur5e-reach-avoid-ppo-plus's (joint-limit penalty 1.0, the paper's parts).
_UR5E_PAPER_OBS = {"env.observation": _MOVING3_OBS, "env.w_joint_limit": 1.0}
register(Experiment(
    "obstacles-moving3", "Reach-avoid with 3 obstacles of random radius (0.05-0.1 m), moving or static, UR5e and Panda",
    "not in the paper (the future work of its Discussion)",
    (Run("ur5e-moving-plus", "ur5e-reach-avoid-ppo-moving3",
         label="ur5e-moving (the preset: plus observation, no joint-limit penalty)"),
     Run("ur5e-static-plus", "ur5e-reach-avoid-ppo-moving3",
         {**_STATIC, "env.observation": tuple(p for p in _MOVING3_PLUS_OBS if p != "obstacle_vel")}, seeds=3,
         label="ur5e-static (plus observation, no joint-limit penalty)"),
     Run("panda-moving", "panda-reach-avoid-ppo-moving3"),
     Run("panda-static", "panda-reach-avoid-ppo-moving3", {**_STATIC, "env.observation": _MOVING3_STATIC_OBS}, seeds=3),
     Run("ur5e-moving", "ur5e-reach-avoid-ppo-moving3", _UR5E_PAPER_OBS,
         label="ur5e-moving, Panda's observation, joint-limit penalty 1.0"),
     Run("ur5e-static", "ur5e-reach-avoid-ppo-moving3",
         {**_UR5E_PAPER_OBS, **_STATIC, "env.observation": _MOVING3_STATIC_OBS}, seeds=3,
         label="ur5e-static, Panda's observation, joint-limit penalty 1.0"),
     Run("panda-static-vel", "panda-reach-avoid-ppo-moving3", _STATIC, seeds=3,
         label="panda-static, velocity observed (always 0)")),
    metrics=AVOID_METRICS, curves=AVOID_CURVES,
    cross=tuple(Cross(f"{robot}-{trained}{plus}", f"{robot}-{trained}{plus}-on-{other}", {"obstacle_motion": motion},
                      label=f"{robot}{' (plus)' if plus else ''}, trained {trained}, evaluated {other}")
                for robot, plus in (("ur5e", "-plus"), ("panda", ""), ("ur5e", ""))
                for trained, other, motion in (("static", "moving", "linear"), ("moving", "static", "static"))),
    paper="Not in the paper; its one static 0.1 m obstacle: UR5e 86.8 % reached (4.8 % obstacle collisions), "
          "Panda 95.2 % (2.5 %).",
    note="Moving: linear paths at 0.05-0.2 m/s bouncing in the sampling cube, radii and velocities observed "
         "(`agents/presets.py`, MOVING_OBSTACLES_3); static: the same obstacles held still and their velocity not "
         "observed, so each agent can be evaluated on the other motion (the cross rows). The UR5e preset has "
         "ur5e-reach-avoid-ppo-plus's options (joint sin/cos and self-collision distances observed, no joint-limit "
         "penalty); ur5e-moving and ur5e-static have the Panda's observation parts and ur5e-reach-avoid-ppo's "
         "joint-limit penalty (a comparison of the two option sets). panda-static-vel observed the velocity (0 in "
         "every episode): its normaliser then scales any motion to the clip, so it is not cross-evaluated "
         "(agents.evaluation.unseen_constants; results/experiments/README.md)."))

# Screening of levers for agents that dodge moving obstacles: one seed a row against the presets' five
# (obstacles-moving3), the winners to be trained at five seeds. The longer budgets are 3-4x the presets', whose
# curves were still rising at their end.
_AHEAD = ("link_obstacle_ahead",)
_JL = {"env.w_joint_limit": 0.05}
"""ur5e-reach-ppo's weak joint-limit penalty."""
_PLUS_AHEAD = {"env.observation": _MOVING3_PLUS_OBS + _AHEAD}
"""The -plus observation of the moving-obstacle task with the links' predicted obstacle distances."""
_AHEAD_MOVING = ("link_obstacle_ahead_moving",)
_LINKS = ("link_pos",)
"""Each link frame origin's world position: with obstacle_pos, the direction from each link to each obstacle."""
_MOVING3 = {"env.num_obstacles": 3, "env.obstacle_motion": "linear", "env.obstacle_radius_range": (0.05, 0.1),
            "env.obstacle_speed_range": (0.05, 0.2)}
"""The -moving3 presets' obstacles (agents/presets.py, MOVING_OBSTACLES_3) on a preset without them."""
register(Experiment(
    "obstacles-dodge", "Among 3 moving obstacles: predicted link distances and longer training (screening: 1 seed a row, 5 for what works)",
    "not in the paper (the future work of its Discussion)",
    (Run("ur5e-ahead", "ur5e-reach-avoid-ppo-moving3", _PLUS_AHEAD, seeds=5,
         label="ur5e, + link_obstacle_ahead"),
     Run("ur5e-ahead-jl", "ur5e-reach-avoid-ppo-moving3", {**_PLUS_AHEAD, **_JL},
         seeds=1, label="ur5e, + link_obstacle_ahead, joint-limit penalty 0.05"),
     Run("ur5e-ahead-cp10", "ur5e-reach-avoid-ppo-moving3", {**_PLUS_AHEAD, "env.collision_penalty": 10.0}, seeds=1,
         label="ur5e, + link_obstacle_ahead, collision penalty 10"),
     Run("ur5e-ahead-jl-cp10", "ur5e-reach-avoid-ppo-moving3", {**_PLUS_AHEAD, **_JL,
                                                                "env.collision_penalty": 10.0},
         seeds=1, label="ur5e, + link_obstacle_ahead, joint-limit penalty 0.05, collision penalty 10"),
     Run("ur5e-ahead-600m", "ur5e-reach-avoid-ppo-moving3", _PLUS_AHEAD, seeds=1,
         num_timesteps=600_000_000, label="ur5e, + link_obstacle_ahead, 600M steps"),
     Run("ur5e-600m", "ur5e-reach-avoid-ppo-moving3", seeds=1, num_timesteps=600_000_000,
         label="ur5e, the preset, 600M steps"),
     Run("panda-ahead", "panda-reach-avoid-ppo-moving3", {"env.observation": _MOVING3_OBS + _AHEAD}, seeds=1,
         label="panda, + link_obstacle_ahead"),
     Run("panda-plus-ahead-400m", "panda-reach-avoid-ppo-moving3", _PLUS_AHEAD,
         seeds=1, num_timesteps=400_000_000, label="panda, plus observation + link_obstacle_ahead, 400M steps"),
     Run("ur5e-sac-fast-ahead", "ur5e-reach-avoid-sac-fast", {**_MOVING3, "env.w_joint_limit": 0.0,
                                                               "env.observation": _MOVING3_PLUS_OBS + _AHEAD},
         seeds=1, num_timesteps=300_000_000,
         label="ur5e, fast SAC (the best static agent), plus observation + link_obstacle_ahead, 300M steps")),
    metrics=AVOID_METRICS, curves=AVOID_CURVES,
    paper="Not in the paper. The presets at five seeds (obstacles-moving3): UR5e 58.8 % reached with 10.1 % obstacle "
          "collisions (192M steps), Panda 63.3 % with 11.8 % (100M); the target is >= 80 % with <= 5 %.",
    note="One seed a row (a screening; what works gets five seeds, as ur5e-ahead). link_obstacle_ahead (envs/config.py, "
         "obstacle_lookahead 0.5 and 1 s): each link's distance to the nearest "
         "obstacle moved on at its current velocity, a prediction the policy otherwise has to learn from the arm's "
         "geometry. Its rows at the presets' budgets isolate the observation; the longer rows ask what more "
         "training gives (both presets' curves were still rising at the end); ur5e-ahead-jl adds ur5e-reach-ppo's weak "
         "joint-limit penalty, since most misses of the shipped policy end with a joint at its limit "
         "(results/obstacles/README.md); the collision-penalty rows (cp10: 10 subtracted on a collision step) aim at the "
         "obstacle collisions, which the penalty cut from 4.8 to 2.0 % on one static obstacle (results/other_levers); "
         "the fast-SAC row tries the learner "
         "that is best on one static obstacle (ur5e-reach-avoid-sac-fast, 90.0 %), without its joint-limit "
         "penalty as the PPO preset here."))

_BEST_UNPENALISED = {
    "ur5e": ("ur5e-reach-avoid-ppo-moving3", {**_PLUS_AHEAD, **_JL},
             "ur5e, + link_obstacle_ahead, joint-limit penalty 0.05", "PPO"),
    "panda": ("panda-reach-avoid-ppo-moving3", _PLUS_AHEAD, "panda, plus observation + link_obstacle_ahead", "PPO"),
    "ur5e-sac": ("ur5e-reach-avoid-sac-fast", {**_MOVING3, **_PLUS_AHEAD, **_JL},
                 "ur5e, fast SAC, plus observation + link_obstacle_ahead, joint-limit penalty 0.05", "SAC"),
    "panda-sac": ("panda-reach-avoid-sac-fast", {**_MOVING3, **_PLUS_AHEAD},
                  "panda, fast SAC, plus observation + link_obstacle_ahead", "SAC"),
}
"""Per robot (and learner), the preset, overrides, label and learner of the best unpenalised settings on the
corrected moving task."""


_SURFACE = {"env.link_distance": "surface"}
"""Each link's distance to an obstacle measured to its capsules' surfaces (observed, and in eq. 3's penalty), where
the paper's measures it from the link frame's origin, which in random poses reads over 10 cm at about half or more
of the contacts along a long link (UR5e upper arm and forearm, Panda link3 and link5; tools/link_distance_probe.py);
the UR5e agents are struck mostly on those two links (results/obstacles)."""

_HELD_BACK = {"algo.multiplier_start": 150_000_000, "algo.multiplier_lr": 6.0}
"""The failure budget's multiplier held at 0 for the first 150M steps, while the agent learns to reach, then grown at
twice the default step (the -from150m-lr6 rows): one grown from the start stops the learning to reach when it grows
fast (results/obstacles)."""

_FASTER = {"env.obstacle_speed_range": (0.05, 0.3)}
"""Obstacles up to 1.5 times the task's top speed in training (the -fast rows, evaluated at the task's speeds by their
cross rows): the agents' collisions grow steeply with the obstacles' speed (results/obstacles)."""


def _variant(name: str, robot: str, more: dict, what: str, num_timesteps: int | None = None, seeds: int = 1) -> Run:
    """A row (one seed unless `seeds`) on `robot`'s best unpenalised settings with `more` overrides, which `what`
    names in the label."""
    preset, overrides, label, _ = _BEST_UNPENALISED[robot]
    label += what
    if num_timesteps is not None:
        label += f", {num_timesteps // 1_000_000}M steps"
    return Run(name, preset, {**overrides, **more}, seeds=seeds, shares=False, num_timesteps=num_timesteps,
               label=label)


def _budget(name: str, robot: str, budget: float, num_timesteps: int | None = None, more: dict | None = None,
            what: str = "", seeds: int = 1) -> Run:
    """A PPO- or SAC-Lagrangian row (`algo.failure_budget`) on `robot`'s best unpenalised settings, with `more`
    overrides that `what` names in the label."""
    learner = _BEST_UNPENALISED[robot][3]
    return _variant(name, robot, {"algo.failure_budget": budget, **(more or {})},
                    f", {learner}-Lagrangian with a {round(budget * 100)} % failure budget{what}", num_timesteps, seeds)


# The same levers on the corrected moving-obstacle task (every robot geom checked, paths drawn clear of the base and
# the first link: results/obstacles/README.md): the runs above trained on the old one and are not mixed with these.
register(Experiment(
    "obstacles-dodge-clear", "Among 3 moving obstacles drawn clear of the base, every robot geom checked: predicted "
    "link distances (the arm held still or moving on), the links' positions, a joint-limit penalty, collision "
    "penalties, a failure budget (PPO- and SAC-Lagrangian), fast SAC, longer training, faster obstacles in "
    "training and link distances to the capsules' surfaces (screening: 1 seed a "
    "row; four long rows have 5 planned)",
    "not in the paper (the future work of its Discussion)",
    (Run("ur5e-ahead-jl", "ur5e-reach-avoid-ppo-moving3", {**_PLUS_AHEAD, **_JL},
         seeds=1, shares=False, label="ur5e, + link_obstacle_ahead, joint-limit penalty 0.05"),
     Run("ur5e-ahead-jl-400m", "ur5e-reach-avoid-ppo-moving3", {**_PLUS_AHEAD, **_JL},
         seeds=5, shares=False, num_timesteps=400_000_000,
         label="ur5e, + link_obstacle_ahead, joint-limit penalty 0.05, 400M steps"),
     Run("ur5e-ahead-jl-cp10", "ur5e-reach-avoid-ppo-moving3",
         {**_PLUS_AHEAD, **_JL, "env.collision_penalty": 10.0}, seeds=1, shares=False,
         label="ur5e, + link_obstacle_ahead, joint-limit penalty 0.05, collision penalty 10"),
     Run("ur5e-ahead-jl-obst0.5", "ur5e-reach-avoid-ppo-moving3",
         {**_PLUS_AHEAD, **_JL, "env.w_obst": 0.5}, seeds=1, shares=False,
         label="ur5e, + link_obstacle_ahead, joint-limit penalty 0.05, link-proximity penalty 0.5 (eq. 3; paper 0.1)"),
     Run("ur5e-ahead-jl-tau0.2", "ur5e-reach-avoid-ppo-moving3",
         {**_PLUS_AHEAD, **_JL, "env.obstacle_tau": 0.2}, seeds=1, shares=False,
         label="ur5e, + link_obstacle_ahead, joint-limit penalty 0.05, link-proximity margin 0.2 m (eq. 3; paper 0.1)"),
     Run("panda-ahead", "panda-reach-avoid-ppo-moving3", {"env.observation": _MOVING3_OBS + _AHEAD}, seeds=1,
         shares=False, label="panda, + link_obstacle_ahead"),
     Run("panda-plus-ahead-300m", "panda-reach-avoid-ppo-moving3", _PLUS_AHEAD,
         seeds=5, shares=False, num_timesteps=300_000_000,
         label="panda, plus observation + link_obstacle_ahead, 300M steps"),
     Run("ur5e-ahead-moving-jl", "ur5e-reach-avoid-ppo-moving3",
         {"env.observation": _MOVING3_PLUS_OBS + _AHEAD + _AHEAD_MOVING, **_JL}, seeds=1, shares=False,
         label="ur5e, + link_obstacle_ahead and link_obstacle_ahead_moving, joint-limit penalty 0.05"),
     Run("ur5e-ahead-vel-jl", "ur5e-reach-avoid-ppo-moving3",
         {"env.observation": _MOVING3_PLUS_OBS + _AHEAD + ("joint_vel",), **_JL}, seeds=1, shares=False,
         label="ur5e, + link_obstacle_ahead and joint_vel (the moving look-ahead's control), joint-limit penalty 0.05"),
     Run("panda-plus-ahead-moving-300m", "panda-reach-avoid-ppo-moving3",
         {"env.observation": _MOVING3_PLUS_OBS + _AHEAD + _AHEAD_MOVING}, seeds=1, shares=False,
         num_timesteps=300_000_000,
         label="panda, plus observation + link_obstacle_ahead and link_obstacle_ahead_moving, 300M steps"),
     Run("ur5e-ahead-jl-cp100", "ur5e-reach-avoid-ppo-moving3",
         {**_PLUS_AHEAD, **_JL, "env.collision_penalty": 100.0}, seeds=1, shares=False,
         label="ur5e, + link_obstacle_ahead, joint-limit penalty 0.05, collision penalty 100"),
     Run("panda-plus-ahead-cp100-300m", "panda-reach-avoid-ppo-moving3",
         {**_PLUS_AHEAD, "env.collision_penalty": 100.0}, seeds=1, shares=False,
         num_timesteps=300_000_000, label="panda, plus observation + link_obstacle_ahead, collision penalty 100, 300M "
                                          "steps"),
     _budget("ur5e-ahead-jl-budget4", "ur5e", 0.04),
     _budget("ur5e-ahead-jl-budget4-lr10", "ur5e", 0.04, more={"algo.multiplier_lr": 10.0},
             what=", multiplier step 10"),
     _budget("panda-plus-ahead-budget4-300m", "panda", 0.04, 300_000_000),
     _budget("ur5e-ahead-jl-budget4-400m", "ur5e", 0.04, 400_000_000),
     _budget("ur5e-ahead-jl-budget3-400m", "ur5e", 0.03, 400_000_000),
     _budget("ur5e-ahead-jl-budget4-from200m-400m", "ur5e", 0.04, 400_000_000,
             more={"algo.multiplier_start": 200_000_000}, what=" from 200M steps on"),
     _budget("panda-plus-ahead-budget4-600m", "panda", 0.04, 600_000_000),
     _budget("ur5e-ahead-jl-budget3-600m", "ur5e", 0.03, 600_000_000, seeds=5),
     _budget("panda-plus-ahead-budget3-600m", "panda", 0.03, 600_000_000),
     Run("ur5e-sac-fast-ahead", "ur5e-reach-avoid-sac-fast",
         {**_MOVING3, "env.observation": _MOVING3_PLUS_OBS + _AHEAD}, seeds=1, shares=False,
         label="ur5e, fast SAC (the preset: joint-limit penalty 1.0), plus observation + link_obstacle_ahead"),
     Run("ur5e-sac-fast-ahead-jl", "ur5e-reach-avoid-sac-fast",
         {**_MOVING3, "env.observation": _MOVING3_PLUS_OBS + _AHEAD, **_JL}, seeds=1, shares=False,
         label="ur5e, fast SAC, plus observation + link_obstacle_ahead, joint-limit penalty 0.05"),
     Run("ur5e-ahead-links-jl", "ur5e-reach-avoid-ppo-moving3",
         {"env.observation": _MOVING3_PLUS_OBS + _AHEAD + _LINKS, **_JL}, seeds=1, shares=False,
         label="ur5e, + link_obstacle_ahead and link_pos, joint-limit penalty 0.05"),
     Run("panda-plus-ahead-links-300m", "panda-reach-avoid-ppo-moving3",
         {"env.observation": _MOVING3_PLUS_OBS + _AHEAD + _LINKS}, seeds=1, shares=False, num_timesteps=300_000_000,
         label="panda, plus observation + link_obstacle_ahead and link_pos, 300M steps"),
     Run("panda-sac-fast-ahead", "panda-reach-avoid-sac-fast",
         {**_MOVING3, "env.observation": _MOVING3_PLUS_OBS + _AHEAD}, seeds=1, shares=False,
         label="panda, fast SAC, plus observation + link_obstacle_ahead"),
     _budget("panda-sac-fast-ahead-budget4", "panda-sac", 0.04),
     _budget("panda-sac-fast-ahead-budget3", "panda-sac", 0.03),
     _budget("panda-sac-fast-ahead-budget3-lr0.01-80m", "panda-sac", 0.03, 80_000_000,
             more={"algo.multiplier_lr": 0.01}, what=", multiplier step 0.01"),
     _budget("ur5e-sac-fast-ahead-jl-budget4", "ur5e-sac", 0.04),
     _budget("panda-sac-fast-ahead-budget3-fast", "panda-sac", 0.03, more=_FASTER, what=", trained at 0.05-0.3 m/s"),
     _budget("ur5e-ahead-jl-budget3-400m-fast", "ur5e", 0.03, 400_000_000, more=_FASTER,
             what=", trained at 0.05-0.3 m/s"),
     Run("ur5e-ahead-jl-surface", "ur5e-reach-avoid-ppo-moving3", {**_PLUS_AHEAD, **_JL, **_SURFACE}, seeds=1,
         shares=False, label="ur5e, + link_obstacle_ahead, joint-limit penalty 0.05, link distances to the capsules' "
                             "surfaces"),
     _budget("panda-sac-fast-ahead-budget3-surface", "panda-sac", 0.03, more=_SURFACE,
             what=", link distances to the capsules' surfaces"),
     _budget("ur5e-ahead-jl-budget3-400m-surface", "ur5e", 0.03, 400_000_000, more=_SURFACE,
             what=", link distances to the capsules' surfaces"),
     _budget("ur5e-ahead-jl-budget3-from150m-lr6-600m", "ur5e", 0.03, 600_000_000, more=_HELD_BACK,
             what=" from 150M steps on, multiplier step 6", seeds=5),
     _budget("ur5e-ahead-jl-budget3-from150m-lr6-800m", "ur5e", 0.03, 800_000_000, more=_HELD_BACK,
             what=" from 150M steps on, multiplier step 6"),
     _variant("ur5e-ahead-jl-g0.99-400m", "ur5e", {"algo.discount": 0.99}, ", discount 0.99 (preset 0.97)",
              400_000_000),
     _variant("panda-plus-ahead-g0.99-300m", "panda", {"algo.discount": 0.99}, ", discount 0.99 (preset 0.98)",
              300_000_000)),
    metrics=AVOID_METRICS, curves=AVOID_CURVES,
    cross=tuple(Cross(run, f"{run}-at-0.05-0.2", {"obstacle_speed_range": (0.05, 0.2)},
                      label=f"{run}, evaluated at the task's 0.05-0.2 m/s")
                for run in ("panda-sac-fast-ahead-budget3-fast", "ur5e-ahead-jl-budget3-400m-fast")),
    paper="Not in the paper. The shipped -moving3 policies (trained on the old task) evaluated on this one: UR5e "
          "68.0 % reached with 4.9 % obstacle collisions, Panda 67.7 % with 6.9 % (results/obstacles/README.md); the "
          "target is >= 80 % with <= 5 %.",
    note="obstacles-dodge's best levers trained again on the corrected task: link_obstacle_ahead (each link's "
         "distance to the nearest obstacle moved on at its current velocity, 0.5 and 1 s ahead), the UR5e with "
         "ur5e-reach-ppo's weak joint-limit penalty (2.2 points more reach on one seed of the old task, against the "
         "five-seed mean), and budgets 2-3x the presets' (their curves were still rising at the end; each within 20 "
         "minutes of one H200). The penalty rows aim at the collisions, which are all avoidable on this task: the "
         "collision penalty (10 subtracted on a collision step) and eq. (3)'s link-proximity penalty, five times "
         "stronger or with twice the margin. On one seed each they moved the collisions by under a point, and most "
         "collisions of the two UR5e policies analysed need the arm's own motion (results/obstacles): the -moving "
         "rows add link_obstacle_ahead_moving, the same prediction with the arm moved on at its joint velocities; "
         "ur5e-ahead-vel-jl observes the joint velocities without it, to tell the prediction from the velocity "
         "information in it. Neither cut the collisions; a third of the UR5e agents' contacts hit an arm that had "
         "reached its target. A collision forfeits the discounted reward still to come: in the target about 2.9 a "
         "step (eq. 1) over the 1 / (1 - discount) steps of the horizon, about 100 for the UR5e (0.97) and 145 for "
         "the Panda (0.98); the cp10 penalty added a tenth of the UR5e's. The cp100 rows double a UR5e collision's "
         "cost and raise a Panda's by about two thirds. The budget rows hand the penalty to PPO-Lagrangian: a "
         "multiplier grown while more than 4 % of the batch's episodes fail and shrunk while fewer do, by 3 (the "
         "default) or 10 times the excess per update: the slower step is meant to let the agent learn to reach "
         "before the penalty grows large. The faster step cost the "
         "reach; at the default step both robots' curves still rose at the end with the multiplier still growing, so "
         "the 400M and 600M rows give them twice the budget (within 20 minutes of one H200 each), the 3 % row for a "
         "margin under the 5 % aim, and the from200m row a curriculum: no multiplier for the first 200M steps (the "
         "unpenalised 400M row's training episodes reach 76.7-77.9 % by then), the budget over the next 200M. Those "
         "left the failed share above the budget throughout and the multiplier growing; the budget3-600m rows train "
         "the 3 % budget (at both lines on the UR5e at 400M) for 600M steps, the UR5e's at five seeds. "
         "The sac-fast rows try fast SAC, the best learner on one static obstacle (ur5e-reach-avoid-sac-fast 90.0 %, "
         "panda-reach-avoid-sac-fast 96.2 % at 200M steps), among the moving obstacles with the same observation, at "
         "its presets' 200M steps; the UR5e with its preset's joint-limit penalty (1.0) and with the PPO rows' 0.05. "
         "The Panda's reached 89.0 % (PPO's five seeds: 86.1 %) and missed 2.4 % (PPO: 4.9 %), four fifths of its "
         "failures collisions (8.3 %): the sac-fast budget rows hand them to SAC-Lagrangian "
         "(twin cost critics of the discounted failures ahead, weighed in the actor's objective by a multiplier "
         "grown by 0.001 per ended episode times the excess over the budget: about the PPO rows' pace per env step); "
         "the 3 % row reached 89.4 % at 6.7 % with the multiplier still growing, and the lr0.01-80m row probes a "
         "ten-times step over 80M steps. "
         "The -fast rows train the 3 % budget rows among faster obstacles (0.05-0.3 m/s) and are evaluated at the "
         "task's speeds by their cross rows: with the obstacles held still the budget agents collide in 2.7-3.0 %, "
         "at the task's speeds in 5.1-6.3 %, at 0.2-0.3 m/s in 10.7-12.3 % (results/obstacles). The -surface rows "
         "measure each link's distance to the obstacles (observed and penalised) to its capsules' surfaces instead of "
         "its frame origin (the paper's d_i), which in random poses reads over 10 cm at about half or more of the contacts "
         "along a long link: on the UR5e (one seed each) the surface distance cut the unbudgeted row's collisions from "
         "7.6 to 5.4 % and left the 3 % budget row's at 4.7 % (4.9 % before), with 1.4 and 2.8 points less reach. "
         "The links rows add link_pos (each link's position: with obstacle_pos, the direction from each link to each "
         "obstacle, which the link distances leave out; the collisions analysed mostly need the arm's own motion) to "
         "ur5e-ahead-jl (80.5 % at 7.6 %) and panda-plus-ahead-300m (86.1 ± 0.7 % at 8.7 ± 0.7 %). The from150m-lr6 "
         "row holds the multiplier at 0 until the agent reaches, then grows it twice as fast as the default: a "
         "multiplier grown early stops the learning to reach (budget4-lr10: 74 by 22M steps, 8 % of the training "
         "episodes reached then and 31 % at 192M), one grown after it does not (from200m: 0 to 84 over 200-400M "
         "steps with the training reach rising from 77.9 to 80.7 %), and the 3 % budget rows' failed share was still "
         "above the budget at 600M with the multiplier at 179-201. The 800M row trains it a third longer, about 17 "
         "minutes of one H200: at 600M its training reach was still rising (76-77 % from 200 to 480M steps, 78.3 % "
         "at 600M) and its failed share stood at 4.7-5.0 %, above the budget; it ended under the 600M row (77.1 % at "
         "4.9 % against 79.3 % at 4.2 %, seed 0 each), its failed share flat at 4.6-4.7 % over its last 200M steps, "
         "so the 600M row has five seeds planned. The g0.99 rows lengthen the discount's "
         "horizon (100 steps, against the UR5e preset's 33 and the Panda's 50), which makes a collision forfeit more "
         "of the reward to come: on one static obstacle it cut the collisions by 32-58 % at 1.2-4.3 points less reach "
         "(the -plus UR5e and the Panda's preset; with the paper's observation the UR5e's reach fell from 71.1 to 10.5"
         " %: results/discount), and on the reach task it took the UR5e from 86.3 to 93.1 %, whose misses had ended at"
         " a pinned joint, as most misses here do; each is the unpenalised long row (ur5e-ahead-jl-400m, "
         "panda-plus-ahead-300m) with that discount."))

_LATENCY_METRICS = AVOID_METRICS + ("steps_in_target", "times_left_target")
register(Experiment(
    "action-latency", "Reach-avoid trained with a one-step action delay, UR5e and Panda",
    "not in the paper (the realism its Discussion names as future work)",
    (Run("ur5e-none", "ur5e-reach-avoid-ppo", seeds=3, label="ur5e, no delay (the preset)"),
     Run("ur5e", "ur5e-reach-avoid-ppo", {"env.action_latency": 1}, seeds=3, label="ur5e, one-step delay"),
     Run("panda-none", "panda-reach-avoid-ppo", seeds=3, label="panda, no delay (the preset)"),
     Run("panda", "panda-reach-avoid-ppo", {"env.action_latency": 1}, seeds=3, label="panda, one-step delay")),
    metrics=_LATENCY_METRICS, curves=AVOID_CURVES + ("episode/steps_in_target",),
    cross=tuple(Cross(robot, f"{robot}-without-delay", {"action_latency": 0},
                      label=f"{robot}, trained with the delay, evaluated without") for robot in ("ur5e", "panda")),
    paper="Not in the paper. The presets' policies, trained without a delay and evaluated with one (CPU, "
          "results/obstacles/README.md): UR5e 84.9 % reached but 5.4 exits from the target an episode (0.03 "
          "without); Panda 55.5 % (96.2 % without), 2.4 of 125 steps in the target.",
    note="Tests whether training with the delay (`env.action_latency=1`: each step applies the previous step's "
         "action, as a real arm's control loop does) restores the precision that the delay takes from the "
         "presets' policies."))
