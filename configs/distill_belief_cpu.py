"""Distillation with a belief decoder (Miki et al. 2022): configs/distill_cpu.py, and a decoder on
the student's LSTM output trained to reconstruct the teacher's true foot patches (4 x 9 heights)
beside the action loss, so that the memory is taught what the ToF zones saw under each foot.
With rsl_rl's distillation settings: the student acts with std 0.1, Adam 1e-3, one pass.

Why: a student that also reads those 36 heights (train.student_privileged_inputs=36) halved the
imitation loss of the sensors-only student and climbed 6x faster (docs/campaign.md, issue
"A privileged teacher and its distillation"): the gap is the foot-local terrain.
"""

from configs import distill_cpu


def get_config():
    c = distill_cpu.get_config()
    c.network.reconstruct = 36  # the teacher's foot patches (the first of its terrain inputs)
    c.ppo.reconstruction_weight = 0.5  # Miki et al. 2022: action loss + 0.5 x reconstruction
    c.network.max_noise_std = 0.1  # rsl_rl's StudentTeacherRecurrent: init_noise_std 0.1
    c.ppo.learning_rate = 1e-3  # rsl_rl's Distillation
    c.ppo.num_epochs = 1
    c.train.run_name = "distill_belief_cpu"
    return c
