"""A teacher limited to what its ToF student can know, sized for 2 cores.

configs/teacher_cpu.py with env.actor_terrain_seen: the actor's terrain inputs (the 4 x 9 foot
patches and the 0.6 m base scan) are true only where a ray of a foot ToF sensor has hit that
terrain cell this episode, else flat ground at the nominal stance, with a seen flag per point
(306 inputs). The belief student of the plain teacher (policies/student until git 88429e8)
recalls 10 cm ahead of its feet at R^2 0.05 (scripts/belief_r2.py): the plain teacher acts on
ground no ToF has looked at; this one has to look (swing a foot over the ground) before it can
know. It starts from the plain teacher (policies/teacher; this run grew from its 2120 = 43.4M
env steps; the flags start at zero). Issue "A privileged teacher and its distillation"; results:
docs/campaign.md.
"""

from configs import teacher_cpu


def get_config():
    c = teacher_cpu.get_config()
    c.env.actor_terrain_seen = True  # terrain inputs only where a foot ray has hit, + flags
    # the plain teacher's guidance bias had decayed to zero by its iteration 1500; a new run
    # counts iterations from 1, so the bias is switched off here rather than paid again
    c.reward.scales.guidance = 0.0
    c.train.init_from = "policies/teacher"  # the plain teacher: gait and stepping, grown inputs
    c.train.run_name = "teacher_seen_cpu"  # run directory name under train.run_root
    return c
