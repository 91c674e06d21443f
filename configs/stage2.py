"""Stage 2: all nine types, harder stage-1 types, real-world sensor degradation, wider initial poses.

Initializes the policy from a stage-1 checkpoint (train.init_from).
"""

from configs import base


def get_config():
    c = base.get_config()
    c.stage = 2  # terrain mix and degradation uppers of stage 2
    c.env.init_roll_pitch_rad = 0.2  # wider initial base orientations ~ U(+-this) [rad]
    c.env.init_joint_noise_rad = 0.15  # wider initial joint angles ~ default + U(+-this) [rad]
    c.env.critic_height_scan = True  # as stage 1 (init_from needs the same critic inputs)
    c.train.run_name = "stage2"  # run directory name under train.run_root
    c.train.init_from = "runs/stage1"  # stage-1 run dir (or checkpoint dir) to initialize from
    return c
