"""The wide teacher (configs/teacher_wide_cpu.py) with the foot-edge penalty on: 2 per foot per s
at a terrain height step (``reward.scales.foot_edge``; Extreme Parkour's ``feet_edge``, the value
the earlier foot-edge A/Bs used).

Why: at stone level 7 the stuck feet of the teacher land a median 4.5 cm past a stone's rim
(41 of 50 within 8 cm; results/teacher_it2800_rims_L7.txt), and the teacher had seen the spot:
it lacks a few cm of placement margin, which is what this term pays for. The ToF policy showed
no effect from it (22M steps, tenth and eleventh sessions), but it could not see the rims; the
teacher reads them.

Price (the wide teacher at 3380, training): 0.10 feet at an edge per step, 362-step episodes
(7.2 s): -2 x 0.10 x 7.2 = ~-1.5 per episode, against +10 for arriving and -15 for a fall.
Refusing the task (standing on the start platform) touches no edge, so the term makes trying
~1.5 dearer than refusing; the plain teacher learned to stop half way at a break-even of p =
0.34 (docs/campaign.md), so its timeouts at difficulty 0.1 are watched. Branched from
policies/teacher_wide (3380) side by side with its continuation; issue "A privileged teacher and
its distillation"; results: docs/campaign.md.
"""

from configs import teacher_wide_cpu


def get_config():
    c = teacher_wide_cpu.get_config()
    c.reward.scales.foot_edge = -2.0  # per foot per s at a height step (teacher_wide_cpu: 0)
    c.train.run_name = "teacher_wide_edge_cpu"  # run directory name under train.run_root
    return c
