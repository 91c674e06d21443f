"""A/B arm (issue "Stones, fourth round", the foot-placement lever): the size-first teacher
(configs/experiments/teacher_stones_cpu.py) also reading its terrain every 5 cm between the 10 cm
samples (env.actor_terrain_fine, foottof/envs/fine_terrain.py: a 5 x 5 patch per foot and a
25 x 17 base scan over the same area, 372 inputs appended).

Why: at the size-first plateau (level 4, d = 0.36: 0.27-0.30 m stones behind 0.10 m gaps) 65 of
100 failures were a foot stuck a median 4.0 cm past a rim the teacher's inputs had shown, which
sample every 10 cm (docs/campaign.md); the paper's ideal scan samples every 5 cm.

Branch: train.init_from the control arm's checkpoint (the line in training, runs/teacher_stones,
at the iteration docs/campaign.md names); the new inputs start with zero weights, so the arm acts
as the control did, and their normalizer entries start as their nearest 10 cm sample's
(fine_terrain.seed_normalizer). Like any init_from: a fresh optimizer at ppo.learning_rate and
fresh curriculum levels U{0..2} (the control keeps its own: a handicap for this arm, ~1M env
steps to climb back). Judged against the control at equal env steps (>= 30M: the gait may
change) by paired evaluations at size-first level 4-5 and on the ensemble.
"""

from configs import teacher_cpu


def get_config():
    c = teacher_cpu.get_config()  # as configs/experiments/teacher_stones_cpu.py, the control:
    c.terrain.stone_curriculum = "size_first"
    c.reward.scales.guidance = 0.0
    c.env.actor_terrain_fine = True  # the arm's one change
    c.train.init_from = "policies/teacher_stones"  # the command line names the branch point
    c.train.run_name = "teacher_fine_cpu"
    return c
