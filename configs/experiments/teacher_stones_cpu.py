"""The foot-edge teacher (configs/teacher_cpu.py) continued on the size-first stone
curriculum (``terrain.stone_curriculum = "size_first"``, foottof.terrain.tiles.STONE_CURRICULA).

Why: at the ensemble the teacher (policies/teacher, 5120, 104.9M env steps) wins 0 of
73 stone episodes and 20 of 27 platform gaps; with the gaps cut to 0.1 m or flat tops it still
wins none, with stones of 0.46-0.51 m it wins 19 of 79 (issue "Stones, fourth round"). On the
gaps-first curriculum it trains its stone types at levels 5.7-6.6 (stones 0.6-0.9 m) and never
stands on the ensemble's 0.27-0.30 m stones, which come only at level 8. Size first puts them at
level 4 (d = 0.36) behind 0.10 m gaps and level tops; the gaps widen to the ensemble's by level
6 and the tops spread by level 8 (the ensemble, unchanged).

Start: a new run from the teacher's parameters and normalizer (train.init_from), fresh curriculum
levels U{0..2} (the old levels name other tiles now) and a fresh optimizer at ppo.learning_rate
(the old run's KL-adaptive rate had fallen to 1.5e-5). Rewards are the teacher's at 5120, so the
price of the task is the one docs/campaign.md gives for it: +10 for arriving, -15 for a fall,
~-1.5 per episode for feet at an edge, 0 for standing still. The guidance bias, which decays by
the run's iteration count (gone at 1500 in the teacher's run), is off: a new run would restart it
(iterations 1-230 of runs/teacher_stones had it on, by mistake; off from 231 on). Issue "Stones,
fourth round"; results: docs/campaign.md.
"""

from configs import teacher_cpu


def get_config():
    c = teacher_cpu.get_config()
    c.terrain.stone_curriculum = "size_first"  # stones shrink first (the default since 12-07)
    c.train.init_from = "policies/teacher"  # 5120: params + normalizer
    c.reward.scales.guidance = 0.0  # as the teacher had it at 5120 (decayed to 0 by 1500)
    c.train.run_name = "teacher_stones_cpu"  # run directory name under train.run_root
    return c
