"""Config sections of the LSTM PPO trainer: c.ppo, c.network and c.train."""

import ml_collections


def get_section() -> ml_collections.ConfigDict:
    """PPO hyper-parameters (rsl_rl / IsaacLab ANYmal-D rough-terrain defaults)."""
    c = ml_collections.ConfigDict()
    c.num_envs = 4096  # parallel environments (GPU-sized; the trainer warns when run on CPU)
    c.num_steps = 24  # rollout length per env per iteration (control steps) = truncated-BPTT length
    c.num_epochs = 5  # passes over each rollout
    c.num_minibatches = 4  # minibatches per epoch, split along the env axis (sequences stay whole)
    c.learning_rate = 1e-3  # initial Adam learning rate
    c.lr_schedule = "adaptive"  # 'adaptive' (rsl_rl KL rule) or 'fixed'
    c.desired_kl = 0.01  # KL target of the adaptive rule: kl > 2x -> lr / 1.5, kl < x/2 -> lr * 1.5
    c.lr_min = 1e-5  # lower clamp of the adaptive learning rate
    c.lr_max = 1e-2  # upper clamp of the adaptive learning rate
    c.gamma = 0.99  # discount per control step
    c.gae_lambda = 0.95  # GAE lambda
    c.clip_param = 0.2  # PPO ratio clip epsilon (also the value clip when clipped value loss is on)
    c.value_loss_coef = 1.0  # weight of the value loss
    c.reconstruction_weight = 0.5  # distillation: weight of the decoder's loss (Miki et al. 2022)
    c.use_clipped_value_loss = True  # clip the value change around the rollout value (rsl_rl)
    c.entropy_coef = 0.005  # weight of the entropy bonus
    c.max_grad_norm = 1.0  # global gradient-norm clip
    c.normalize_advantage = True  # standardize advantages over the whole rollout batch
    # left-right mirror symmetry: the mirrored copy of every rollout sequence joins its minibatch,
    # starting from the LSTM carry the policy has on the mirrored episode (foottof.ppo.symmetry)
    c.symmetry = False
    return c


def get_network_section() -> ml_collections.ConfigDict:
    """LSTM actor-critic sizes (rsl_rl ActorCriticRecurrent defaults)."""
    c = ml_collections.ConfigDict()
    c.policy = "lstm"  # 'lstm' (recurrent) or 'mlp' (memoryless, same MLP heads, no LSTM)
    c.lstm_hidden_size = 256  # LSTM units per layer (actor and critic each have their own LSTM)
    c.lstm_num_layers = 1  # stacked LSTM layers
    c.actor_hidden = (512, 256, 128)  # actor MLP head hidden widths after the LSTM
    c.critic_hidden = (512, 256, 128)  # critic MLP head hidden widths after the LSTM
    c.obs_skip = False  # True: each head reads [LSTM output, normalized obs] (lstm policy only)
    # distillation: a decoder on the actor's memory reconstructs the first N privileged inputs
    # of the teacher (36: the foot patches), trained with ppo.reconstruction_weight; 0: none
    c.reconstruct = 0
    c.activation = "elu"  # MLP activation: 'elu', 'relu', 'tanh' or 'silu'
    c.init_noise_std = 1.0  # initial action std (state-independent, learned as log std)
    c.max_noise_std = 0.0  # cap on the learned action std; 0 = no cap (rsl_rl has none)
    c.normalize_observations = True  # running mean/std normalization of actor and critic obs
    c.normalizer_std_eps = 1e-4  # added to the running variance: std >= 1e-2 (rsl_rl eps 1e-2)
    return c


def get_train_section() -> ml_collections.ConfigDict:
    """Run loop: length, logging, checkpoints."""
    c = ml_collections.ConfigDict()
    c.num_iterations = 1500  # training iterations (rollout + update) in the whole run
    c.run_root = "runs"  # parent folder of run directories (train.py makes runs/<name>)
    c.checkpoint_every = 50  # save a checkpoint every N iterations (and always at the end)
    c.max_checkpoints = 5  # checkpoints kept on disk (oldest deleted first)
    c.checkpoint_env_state = True  # save env state + LSTM carries: resume is bit-exact
    c.tensorboard = True  # write TensorBoard event files (tensorboardX) next to metrics.csv
    c.teacher = ""  # a run or policy folder: distil it into this run's policy (DAgger), not PPO
    # resume a distillation run whose train.teacher now holds another checkpoint (teacher.json)
    c.teacher_change_ok = False
    # distillation diagnostic: the student also reads the first N of the teacher's terrain inputs
    # (36: the true foot patches; 153: all), to measure which of them the imitation gap is over
    c.student_privileged_inputs = 0
    c.log_every = 1  # print a progress line every N iterations (CSV/TensorBoard get every one)
    return c
