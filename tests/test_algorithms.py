"""foottof.ppo.algorithms: the training step's algorithm is chosen once from the config."""

import functools

from configs import smoke
from foottof.ppo import algorithms, distill, losses
from foottof.ppo import train as train_lib


def test_the_config_picks_distillation_where_a_teacher_is_set_else_ppo():
    cfg = smoke.get_config()
    cfg.ppo.clip_param = 0.3
    cfg.ppo.entropy_coef = 0.004
    ppo = train_lib.Settings.from_config(cfg).algorithm
    assert ppo.name == "ppo"
    assert isinstance(ppo.loss, functools.partial) and ppo.loss.func is losses.ppo_loss
    assert ppo.loss.keywords == {
        "clip_param": 0.3,
        "value_loss_coef": cfg.ppo.value_loss_coef,
        "entropy_coef": 0.004,
        "use_clipped_value_loss": cfg.ppo.use_clipped_value_loss,
    }
    cfg.train.teacher = "policies/teacher"
    assert train_lib.Settings.from_config(cfg).algorithm.name == "distillation"


def test_distillation_passes_its_reconstruction_weight_and_ignores_the_kl_envs(monkeypatch):
    seen = []
    monkeypatch.setattr(distill, "distill_loss", lambda *args: seen.append(args) or (0.0, {}))
    loss = algorithms.distillation(0.5).loss
    loss("params", "networks", "normalizer", "batch", kl_envs=3)
    assert seen == [("params", "networks", "normalizer", "batch", 0.5)]
