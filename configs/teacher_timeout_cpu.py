"""The privileged teacher with a timeout priced like a fall (configs/teacher_cpu.py).

Why: from 2800 to 3200 (8.2M env steps) the plain teacher's mean-action success at difficulty
0.1 fell from 0.900 to 0.695 (paired, 49 / 8, p = 3e-8) while its falls fell (15 -> 12; at 0.36
25 -> 7, at level 7 157 -> 134): 49 of 200 episodes now time out at a mean 0.2 m/s, stopped
about half way (progress 0.51). The arrive task makes that pay at the frontier. From half way
(~5 s left, ~2.2 m to go), discounted at gamma 0.998: stopping costs the stall penalty (-2 per
s, ~-7.8) and keeps a little of the window (~+1.0): ~-6.8; trying pays ~6 x p for arriving and
~-13.5 x (1 - p) for the fall that comes within a second. They break even at p = 0.34, the
success rate the curriculum holds training at (0.35): the teacher is taught that stopping is as
good as trying exactly where it learns. Here the deadline away from the goal costs 15, as a
fall does (``reward.scales.timeout``): stopping half way costs ~-16, below a fall, and trying
beats stopping at any p > 0; from the start, refusing costs ~-30 undiscounted (was ~-15.5)
against -15 for a fall and up to +10 for arriving. Branched from policies/teacher (3210);
issue "A privileged teacher and its distillation"; results: docs/campaign.md.
"""

from configs import teacher_cpu


def get_config():
    c = teacher_cpu.get_config()
    c.reward.scales.timeout = -15.0  # the deadline away from the goal, as a fall (teacher_cpu: 0)
    c.train.run_name = "teacher_timeout_cpu"  # run directory name under train.run_root
    return c
