"""PPO fine-tuning of the distilled ToF student (policies/student: configs/distill_seen_cpu.py) on
the arrive task.

configs/stage1_arrive_cpu.py started from the student (params, normalizer and the teacher's
critic it carries), with the guidance bias off from the first iteration: the student has learned
the task from its teacher, the bias would only pay speed again.
"""

from configs import stage1_arrive_cpu


def get_config():
    c = stage1_arrive_cpu.get_config()
    c.train.init_from = "policies/student"  # the distilled student (run or policy folder)
    # the student's belief decoder (configs/distill_belief_cpu.py): kept, not trained by PPO
    c.network.reconstruct = 36
    c.reward.guidance_decay_start_iteration = 0
    c.reward.guidance_decay_end_iteration = 1  # weight 0 from the first iteration on
    c.train.run_name = "student_finetune_cpu"
    return c
