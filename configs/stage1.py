"""Stage 1: the five stage-1 terrain types, low sensor degradation, GPU-sized (4096 envs)."""

from configs import base


def get_config():
    c = base.get_config()
    c.stage = 1  # terrain mix and degradation uppers of stage 1
    c.env.critic_height_scan = True  # privileged base-centred height scan for the critic
    c.train.run_name = "stage1"  # run directory name under train.run_root
    return c
