"""Stage 2 sized for a 2-core CPU: stage2.py's terrain (all nine types, stage-1 types from
difficulty 0.4), real-world sensor degradation and wider initial poses, with stage1_cpu.py's
network, envs and rollout so that it starts from the CPU stage-1 policy (policies/stage1)."""

from configs import stage1_cpu


def get_config():
    c = stage1_cpu.get_config()  # CPU network, 512 envs x 40 steps, critic height scan
    c.stage = 2  # terrain mix and degradation uppers of stage 2 (configs/_terrain.py, _sensor.py)
    c.env.init_roll_pitch_rad = 0.2  # wider initial base orientations ~ U(+-this) [rad]
    c.env.init_joint_noise_rad = 0.15  # wider initial joint angles ~ default + U(+-this) [rad]
    c.train.init_from = "policies/stage1"  # the CPU stage-1 policy: params + normalizer
    c.train.run_name = "stage2_cpu"  # run directory name under train.run_root
    return c
