"""The privileged teacher with an actor of about the anchors' size: heads that read the observation
beside the LSTM (network.obs_skip) and an actor head of 512-256 (configs/teacher_cpu.py: 128-64).

Why: at stone level 7 the plain teacher (2800, 100 episodes, seed 4242) ends 50 episodes with
a foot stuck in a gap, 42 of them stepped in from a swing onto a spot its own terrain inputs
had shown as a gap a median 0.6 s before. The task already prices that step at once (a foot
12 cm into a gap ends the episode, -15) and the foot-edge term would price only the 8 that slid
off a rim; what the teacher lacks is the mapping from 153 terrain heights to a foot placement,
and every one of them reaches its 128-64 head only through a 64-unit LSTM. The anchors' actors
read the height scan directly with 512-256-128 MLPs (legged_gym, rsl_rl, Isaac Lab's ANYmal-D
rough task, Extreme Parkour's and Agarwal et al.'s teachers). The LSTM stays for memory; the
grown run starts as the saved policy (foottof.ppo.input_growth.grow_width: new units and
observation rows cut off from the saved units), so no gait is relearned. Two layers, not the
anchors' three: a layer cannot be added without changing the saved policy (ELU is not the
identity), widening can. Branched from
policies/teacher (2800) side by side with the plain continuation; issue "A privileged teacher
and its distillation"; results: docs/campaign.md.
"""

from configs import teacher_cpu


def get_config():
    c = teacher_cpu.get_config()
    c.network.obs_skip = True  # heads read [LSTM output, normalized observation]
    c.network.actor_hidden = (512, 256)  # teacher_cpu: (128, 64); legged_gym: (512, 256, 128)
    c.train.run_name = "teacher_wide_cpu"  # run directory name under train.run_root
    return c
