"""The wide teacher with the foot-edge term (configs/teacher_wide_edge_cpu.py) and the stall
penalty's grace cut from 2 s to the spawn landing's 0.5 s (reward.stall_grace_s).

Why: the wide teacher's mean action dawdles at the start. At difficulty 0.1 (3920, 200
episodes, seed 4242, mean actions) its timeouts reached 0.1 of the course (~0.46 m) after a
median 312 steps (6.2 s), its successes after 166 (3.3 s; walking at 0.6 m/s that is ~2.5 s
standing first); 26 of 28 timeouts were walking at the deadline, behind, not stopped. The
first 2 s of an episode are free to stand in (the grace), a 10 s episode over ~4.7 m leaves
~2 s of slack at the policy's 0.6 m/s, and the mean action (what a robot and evaluate.py run)
starts later than the sampled one (at std 0.1: 18 episodes past 250 steps, not 35).

Pricing (unscaled; reward.overall_scale 0.1 scales all): standing at the start now costs -2 per
s from 0.5 s instead of 2 s (-3 more for a 2 s wait); walking off at once costs nothing more;
refusing costs -19 instead of -16 over an episode against +10 for arriving and -15 for a fall.
Branched from policies/teacher_wide_edge (3920) side by side with the edge continuation; issue
"A privileged teacher and its distillation"; results: docs/campaign.md.
"""

from configs import teacher_wide_edge_cpu


def get_config():
    c = teacher_wide_edge_cpu.get_config()
    c.reward.stall_grace_s = 0.5  # no stall penalty before this [s] (teacher_wide_edge_cpu: 2)
    c.train.run_name = "teacher_wide_edge_prompt_cpu"  # run directory name under train.run_root
    return c
