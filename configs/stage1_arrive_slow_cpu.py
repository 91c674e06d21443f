"""The arrive task with the rest of the recipe: a curriculum that holds training success near
one half, and the paper's regularizer of "overly aggressive gaits", sized for 2 cores.

configs/stage1_arrive_cpu.py (the anchors' goal-reaching task) with two changes, made as an A/B
branch of that run after its guidance bias is gone (copy the run, resume with this config):

- curriculum: an episode that neither reached the goal nor covered 0.8 of the way without a
  fall moves down (terrain.down_progress_frac 0.5 -> 0.8, = up_progress_frac). Promotions and
  demotions balance where about half the episodes succeed, not a third: the anchors hold
  success high, and at s = 0.5, f = 0.5 a try is worth ~4 more than a refusal (at the arrive
  run's s = 0.35, f = 0.65: ~1; docs/campaign.md, the pricing).
- overspeed: -1.5 per s per m/s of horizontal base speed above 0.6 m/s (the paper's robot:
  0.52 m/s; the window needs ~0.5 m/s to arrive in time). At 0.9 m/s for the ~4.7 s of the
  course it costs ~2.1, at 1.2 m/s ~3.2 (a fall costs 15, the task pays up to 10); walking at
  0.6 m/s costs nothing, so slowing down is paid and refusing is not.

Issue "Stones, third round"; results: docs/campaign.md.
"""

from configs import stage1_arrive_cpu


def get_config():
    c = stage1_arrive_cpu.get_config()
    c.terrain.down_progress_frac = 0.8  # = up_progress_frac: success is held near one half
    c.reward.overspeed_mps = 0.6  # the paper's 0.52 m/s, with a margin
    c.reward.scales.overspeed = -1.5  # per s per m/s above overspeed_mps
    c.train.run_name = "stage1_arrive_slow_cpu"  # run directory name under train.run_root
    return c
