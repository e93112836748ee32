"""PPO+ASOR on the lava world through real RLlib: rewards, aux training, checkpoints."""

import copy
import math

import numpy as np
import pytest
import torch
from ray.rllib.algorithms.algorithm import Algorithm
from ray.rllib.algorithms.ppo import PPOConfig
from ray.rllib.core import DEFAULT_MODULE_ID, Columns
from ray.rllib.core.rl_module.multi_rl_module import MultiRLModule
from ray.rllib.utils.metrics import NUM_ENV_STEPS_SAMPLED_LIFETIME

import rllib_asor
import rllib_asor.envs  # noqa: F401  (registers rllib_asor/LavaWorld-v0)
from rllib_asor.asor.reward import reward_bonus
from rllib_asor.asor.trainer import AsorTrainer
from rllib_asor.rllib.connector import AsorRewardConnector
from rllib_asor.rllib.modules import TRAINER_STATE

DISC = "asor_disc.default_policy"


def lava_ppo_config() -> PPOConfig:
    """Plain PPO on the lava world, small and local (2 envs, batch 256, 2 epochs of 64)."""
    return (
        PPOConfig()
        .environment("rllib_asor/LavaWorld-v0")
        .env_runners(num_env_runners=0, num_envs_per_env_runner=2)
        .training(train_batch_size=256, minibatch_size=64, num_epochs=2, lr=1e-3)
        .rl_module(model_config={"fcnet_hiddens": [32, 32]})
        .debugging(seed=0)
    )


def lava_ppo(**asor):
    """PPO+ASOR on the lava world; the paper preset unless `preset` says otherwise."""
    config = lava_ppo_config()
    defaults = {"preset": "paper", "lambda_": 0.1, "seed": 0}
    if asor.get("preset") == "robust":
        defaults = {"seed": 0}
    return rllib_asor.with_asor(config, **(defaults | asor))


@pytest.fixture(scope="module")
def algo(ray_session):
    algo = lava_ppo().build_algo()
    yield algo
    algo.stop()


def sample_episodes(algo, n):
    """Fresh copies: the Learner pipeline edits episodes in place (as after a remote transfer)."""
    return copy.deepcopy(algo.env_runner.sample(num_timesteps=n, random_actions=False))


def asor_trainer(algo) -> AsorTrainer:
    return algo.learner_group._learner.module[DISC].unwrapped().trainer


def aux_state(algo):
    """ASOR's networks and statistics by name ("state.disc...", "proxy.rnd...")."""
    return {k: v.clone() for k, v in asor_trainer(algo).state_dict().items()}


def test_with_asor_wires_learner_modules_and_settings(algo):
    assert set(algo.learner_group._learner.module.keys()) == {DEFAULT_MODULE_ID, DISC}
    assert algo.config.learner_config_dict["asor"]["lambda_"] == 0.1
    # learner-only: the (single-agent) env runner holds just the policy, no aux modules.
    assert not isinstance(algo.env_runner.module, MultiRLModule)


def test_paper_preset_rewards_change_by_lambda_times_log_omega(algo):
    learner = algo.learner_group._learner
    episodes = sample_episodes(algo, 200)
    env_total = sum(float(np.sum(e.get_rewards())) for e in episodes)
    disc_before = copy.deepcopy(asor_trainer(algo).state.disc)  # trained after the bonus
    trained = []
    real_train = AsorTrainer.train_discriminator

    def spy(self, x, y, *args, **kwargs):
        trained.append((x, y))
        return real_train(self, x, y, *args, **kwargs)

    AsorTrainer.train_discriminator = spy
    try:
        batch = learner._learner_connector(
            rl_module=learner.module,
            batch={},
            episodes=episodes,
            shared_data={},
            metrics=learner.metrics,
        )
    finally:
        AsorTrainer.train_discriminator = real_train
    pb = batch[DEFAULT_MODULE_ID]
    valid = pb[Columns.LOSS_MASK].bool()
    ((disc_obs, labels),) = trained
    with torch.no_grad():
        logits = disc_before(disc_obs)
    expected = env_total + 0.1 * reward_bonus(logits).sum().item()
    assert pb[Columns.REWARDS][valid].sum().item() == pytest.approx(expected, rel=1e-4, abs=1e-4)
    # The discriminator trains on exactly the valid steps, ~ρ1ρ2 of them labelled real.
    assert disc_obs.shape[0] == int(valid.sum())
    assert 0.2 <= labels.mean().item() <= 0.3


def test_two_iterations_train_aux_modules_and_report_metrics(algo):
    before = aux_state(algo)
    for _ in range(2):
        result = algo.train()
    after = aux_state(algo)
    for net in ("state.disc.net.", "proxy.rnd.predictor."):
        changed = [k for k in before if k.startswith(net) and not torch.equal(before[k], after[k])]
        assert changed, f"{net} did not change"
    count, target = "proxy.rnd.obs_rms.count", "proxy.rnd.target.0.weight"
    assert not torch.equal(before[count], after[count])
    assert torch.equal(before[target], after[target])
    asor = result["asor"]
    for key in (
        "disc_loss",
        "disc_acc",
        "aug_reward_mean",
        "aug_reward_min",
        "aug_reward_max",
        "real_fraction",
        "rnd_loss",
        "lambda",
        "js_estimate",
    ):
        assert np.isfinite(asor[key]), key
    assert asor["lambda"] == 0.1  # the setting reached the connector (paper preset: absolute λ)


def test_checkpoint_restores_aux_weights_and_normaliser(algo, tmp_path):
    algo.train()
    algo.save_to_path(str(tmp_path))
    saved = aux_state(algo)
    restored = Algorithm.from_checkpoint(str(tmp_path))
    try:
        got = aux_state(restored)
        assert saved.keys() == got.keys()
        for k in saved:
            assert torch.equal(saved[k], got[k]), k
        # the optimisers' moments too
        mine, theirs = asor_trainer(algo), asor_trainer(restored)
        for opt in ("disc_optimizer", "proxy_optimizer"):
            a, b = getattr(mine, opt).state_dict(), getattr(theirs, opt).state_dict()
            for i, moments in a["state"].items():
                for name, value in moments.items():
                    assert torch.equal(value, b["state"][i][name]), (opt, i, name)
        assert (
            restored.config.learner_config_dict["asor"] == algo.config.learner_config_dict["asor"]
        )
    finally:
        restored.stop()


def test_asor_piece_goes_before_gae_subclasses_and_refuses_a_pipeline_without_gae(algo):
    from ray.rllib.connectors.learner import GeneralAdvantageEstimation

    class MyGAE(GeneralAdvantageEstimation):
        pass

    learner = algo.learner_group._learner
    pipeline = learner._learner_connector
    saved = list(pipeline.connectors)
    try:
        pipeline.connectors = [
            MyGAE(gamma=0.99, lambda_=0.95) if isinstance(c, GeneralAdvantageEstimation) else c
            for c in saved
            if not isinstance(c, AsorRewardConnector)
        ]
        learner._insert_asor_piece()
        names = [type(c).__name__ for c in pipeline.connectors]
        assert names.index("AsorRewardConnector") == names.index("MyGAE") - 1
        pipeline.connectors = [
            c
            for c in pipeline.connectors
            if not isinstance(c, (AsorRewardConnector, GeneralAdvantageEstimation))
        ]
        with pytest.raises(ValueError, match="before GeneralAdvantageEstimation"):
            learner._insert_asor_piece()
    finally:
        pipeline.connectors = saved


def test_nan_observation_is_a_clear_error(algo):
    learner = algo.learner_group._learner
    piece = next(
        c for c in learner._learner_connector.connectors if isinstance(c, AsorRewardConnector)
    )
    episodes = sample_episodes(algo, 64)
    batch = learner._learner_connector(
        rl_module=learner.module, batch={}, episodes=episodes, shared_data={}, metrics=None
    )
    pb = batch[DEFAULT_MODULE_ID]
    first_valid = int(torch.nonzero(pb[Columns.LOSS_MASK])[0])
    pb[Columns.OBS][first_valid, 0] = float("nan")
    with pytest.raises(ValueError, match="NaN/inf"):
        piece(rl_module=learner.module, batch=batch, episodes=episodes)


def test_srpo_mode_builds_no_proxy(ray_session):
    algo = lava_ppo(mode="srpo").build_algo()
    try:
        assert asor_trainer(algo).proxy is None
        result = algo.train()
        assert "rnd_loss" not in result["asor"] and result["asor"][
            "real_fraction"
        ] == pytest.approx(0.5, abs=0.05)
    finally:
        algo.stop()


@pytest.mark.parametrize(
    "bad",
    [
        {"rho_value": 0.0},
        {"lambda_": -1.0},
        {"proxy": "counts"},
        {"aux_epochs": 0},
        {"aux_epochs": "1"},
    ],
)
def test_with_asor_rejects_bad_settings(bad):
    with pytest.raises(ValueError, match="allowed"):
        lava_ppo(**bad)


def test_aux_epochs_takes_fractions_and_defaults_to_unset():
    from rllib_asor.asor.config import AsorConfig

    assert AsorConfig().aux_epochs is None
    assert AsorConfig(aux_epochs=0.25).aux_epochs == 0.25


def test_with_asor_rejects_unsupported_algorithm():
    from ray.rllib.algorithms.dqn import DQNConfig

    with pytest.raises(ValueError, match="supported"):
        rllib_asor.with_asor(DQNConfig().environment("CartPole-v1"))


def test_aux_modules_get_aux_epochs_passes_while_policy_gets_num_epochs(algo):
    learner = algo.learner_group._learner

    def adam_steps(optimizer):
        state = optimizer.state
        return max(int(s["step"]) for s in state.values()) if state else 0

    optimizers = {
        "policy": learner.get_optimizer(module_id=DEFAULT_MODULE_ID),
        "disc": asor_trainer(algo).disc_optimizer,
        "proxy": asor_trainer(algo).proxy_optimizer,
    }
    before = {m: adam_steps(o) for m, o in optimizers.items()}
    algo.train()
    steps = {m: adam_steps(o) - before[m] for m, o in optimizers.items()}
    # num_epochs=2 for the policy, aux_epochs=1 (default) for the discriminator and RND.
    assert steps["disc"] == steps["proxy"]
    assert 0.35 * steps["policy"] <= steps["disc"] <= 0.65 * steps["policy"]


def test_with_asor_makes_our_env_ids_buildable_on_remote_env_runners(ray_session):
    from ray.tune.registry import ENV_CREATOR, _global_registry

    config = lava_ppo().env_runners(num_env_runners=1, num_cpus_per_env_runner=0.5)
    assert _global_registry.contains(ENV_CREATOR, "rllib_asor/LavaWorld-v0")
    algo = config.build_algo()
    try:
        assert algo.train()["env_runners"]["num_env_steps_sampled"] > 0
    finally:
        algo.stop()


def test_rnd_per_dynamics_counts_with_the_envs_dynamics_ids(ray_session):
    algo = lava_ppo(proxy="rnd_per_dynamics", dynamics_buckets=8).build_algo()
    try:
        result = algo.train()
        proxy = asor_trainer(algo).proxy.rnd
        # The lava rows 2..5 are the dynamics ids: exactly their buckets have been seen.
        assert torch.nonzero(proxy.seen).flatten().tolist() == [2, 3, 4, 5]
        assert np.isfinite(result["asor"]["rnd_loss"]) and result["asor"]["real_fraction"] > 0
    finally:
        algo.stop()


# ------------------------------------------------------------------ the robust default
@pytest.fixture(scope="module")
def robust(ray_session):
    algo = lava_ppo(preset="robust").build_algo()
    yield algo
    algo.stop()


def test_default_is_the_robust_preset():
    config = lava_ppo(preset="robust").learner_config_dict["asor"]
    assert config["preset"] == "robust" and config["real_source"] == "archive"
    assert config["reward_form"] == "logit" and config["lambda_relative"]


def test_robust_rewards_change_by_the_updates_delta_and_archive_fills(robust):
    learner = robust.learner_group._learner
    state = asor_trainer(robust).state
    real_train, trained = AsorTrainer.train_discriminator, []

    def spy(self, x, y, *args, **kwargs):
        trained.append(y)
        return real_train(self, x, y, *args, **kwargs)

    for _ in range(3):
        result = robust.train()
    assert len(state.archive) > 0 and result["asor"]["archive_states"] == len(state.archive)
    episodes = sample_episodes(robust, 300)
    env_total = sum(float(np.sum(e.get_rewards())) for e in episodes)
    metrics = type(learner.metrics)()
    AsorTrainer.train_discriminator = spy
    try:
        batch = learner._learner_connector(
            rl_module=learner.module, batch={}, episodes=episodes, shared_data={}, metrics=metrics
        )
    finally:
        AsorTrainer.train_discriminator = real_train
    pb = batch[DEFAULT_MODULE_ID]
    valid = pb[Columns.LOSS_MASK].bool()
    stats = metrics.reduce()[DISC]
    added = pb[Columns.REWARDS][valid].sum().item() - env_total
    assert added == pytest.approx(stats["aug_reward_mean"] * int(valid.sum()), abs=1e-3)
    # Bounded: |λ(γb′ − b)| ≤ (1 + γ)·λ·bonus_clip, λ already × the reward scale.
    bound = stats["lambda"] * 2.0 * 3.0 + 1e-6
    assert -bound <= stats["aug_reward_min"] and stats["aug_reward_max"] <= bound
    # The discriminator batch: archive states (label 1) and the whole batch (label 0).
    (labels,) = trained
    assert int((labels == 0).sum()) == int(valid.sum()) and int((labels == 1).sum()) > 0


def test_policy_gets_num_epochs_even_when_the_discriminator_batch_is_longer(robust):
    """The discriminator's batch (archive states + the whole batch) is longer than the policy's;
    it trains outside the policy's minibatches, which keep PPO's count."""
    learner = robust.learner_group._learner
    while len(asor_trainer(robust).state.archive) == 0:
        robust.train()
    episodes = sample_episodes(robust, 256)
    policy_rows = sum(len(e) + 1 for e in episodes)  # + PPO's bootstrap row per episode chunk
    optimizer = learner.get_optimizer(module_id=DEFAULT_MODULE_ID)
    before = max(int(s["step"]) for s in optimizer.state.values())
    learner.update(
        episodes=episodes,
        timesteps={NUM_ENV_STEPS_SAMPLED_LIFETIME: 10_000},
        num_epochs=2,
        minibatch_size=64,
        shuffle_batch_per_epoch=True,
    )
    steps = max(int(s["step"]) for s in optimizer.state.values()) - before
    assert steps == math.ceil(2 * policy_rows / 64)


def test_robust_checkpoint_restores_the_archive_and_normalisers(robust, tmp_path):
    robust.train()
    robust.save_to_path(str(tmp_path))
    saved = aux_state(robust)
    assert saved["state.archive.size"].sum() > 0
    restored = Algorithm.from_checkpoint(str(tmp_path))
    try:
        got = aux_state(restored)
        for k in (
            "state.archive.features",
            "state.archive.returns",
            "state.bonus_rms.mean",
            "state.reward_rms.var",
            "state.critic_ready",
            "state.disc.input_rms.count",
        ):
            assert torch.equal(saved[k], got[k]), k
    finally:
        restored.stop()


def test_learner_only_modules_send_nothing_to_env_runners(robust):
    """The weight sync asks for every module the update reported, ASOR's included; their
    inference-only state is empty (runners hold no such module), their full state is not."""
    from ray.rllib.core import COMPONENT_LEARNER, COMPONENT_RL_MODULE

    robust.train()
    ids = [DEFAULT_MODULE_ID, DISC]
    comps = [f"{COMPONENT_LEARNER}/{COMPONENT_RL_MODULE}/{m}" for m in ids]
    lg = robust.learner_group
    sent = lg.get_state(components=comps, inference_only=True)[COMPONENT_LEARNER]
    assert sent[COMPONENT_RL_MODULE][DISC] == {}
    assert sent[COMPONENT_RL_MODULE][DEFAULT_MODULE_ID]  # the policy's weights still go
    full = lg.get_state(components=comps)[COMPONENT_LEARNER][COMPONENT_RL_MODULE]
    modules = full[DISC][TRAINER_STATE]["modules"]
    assert modules["state.archive.size"].sum() > 0 and "proxy.rnd.predictor.0.weight" in modules
    # what PPO's training_step syncs reaches the runner and changes its policy's weights
    robust.env_runner_group.sync_weights(
        from_worker_or_learner_group=lg, policies=set(ids), inference_only=True
    )
    runner = robust.env_runner.module
    policy = lg._learner.module[DEFAULT_MODULE_ID]
    for name, tensor in runner.state_dict().items():
        assert torch.equal(tensor, policy.state_dict()[name]), name


def _cartpole_ppo(reward_scale: float):
    import gymnasium as gym
    from ray.tune.registry import register_env

    name = f"cartpole_x{reward_scale:g}"
    register_env(
        name,
        lambda cfg: gym.wrappers.TransformReward(
            gym.make("CartPole-v1"), lambda r: r * reward_scale
        ),
    )
    config = (
        PPOConfig()
        .environment(name)
        .env_runners(num_env_runners=0, num_envs_per_env_runner=4)
        .training(
            train_batch_size=512,
            minibatch_size=128,
            num_epochs=2,
            lr=1e-3,
            # No value-loss clipping: RLlib's default (10) keeps a critic of returns ~1e4 from
            # ranking states for many iterations, and ASOR waits for it (λ warm-up).
            vf_clip_param=float("inf"),
        )
        .rl_module(model_config={"fcnet_hiddens": [32, 32]})
        .debugging(seed=0)
    )
    return rllib_asor.with_asor(config, seed=0)


def test_robust_bonus_is_scale_free_and_finite_on_a_constant_reward(ray_session):
    """CartPole pays 1 per step (a constant reward); ×100 must not change the bonus's share."""
    shares = {}
    for scale in (1.0, 100.0):
        algo = _cartpole_ppo(scale).build_algo()
        try:
            for _ in range(10):  # until the critic ranks states (λ warm-up) and D_P exists
                asor = algo.train()["asor"]
                if asor["active"] == 1.0:
                    break
        finally:
            algo.stop()
        assert asor["active"] == 1.0 and asor["reward_scale"] == pytest.approx(scale, rel=1e-3)
        for key in ("aug_reward_min", "aug_reward_max", "potential_share", "bonus_share"):
            assert np.isfinite(asor[key]), key
        shares[scale] = asor["potential_share"]
    assert shares[1.0] > 0 and 0.5 <= shares[100.0] / shares[1.0] <= 2.0


def test_robust_ppo_with_the_ensemble_proxy_still_fills_the_archive(ray_session):
    """PPO batches then carry NEXT_OBS too; the on-policy chunk structure must still be used."""
    algo = lava_ppo(preset="robust", proxy="ensemble").build_algo()
    try:
        for _ in range(3):
            asor = algo.train()["asor"]
        assert asor["archive_states"] > 0 and np.isfinite(asor["critic_ev"])
        assert np.isfinite(asor["ensemble_loss"])
    finally:
        algo.stop()


def test_nan_gradients_are_zeroed_with_one_check_as_rllib_does(ray_session, caplog):
    """The one-check speed-up of `LeanPPOTorchLearner` (which ASOR keeps, not adds), with
    ASOR's modules among the parameters."""
    from rllib_asor.algorithms.ppo.lean import LeanPPOTorchLearner

    config = lava_ppo_config().learners(learner_class=LeanPPOTorchLearner)
    algo = rllib_asor.with_asor(config, preset="paper", lambda_=0.1, seed=0).build_algo()
    try:
        learner = algo.learner_group._learner
        assert learner._check_gradients_once and learner.config.torch_skip_nan_gradients
        params = learner._params
        before = {pid: p.detach().clone() for pid, p in params.items()}
        grads = {pid: torch.full_like(p, 0.5) for pid, p in params.items()}
        bad = next(iter(grads))
        grads[bad][..., 0] = float("nan")
        with caplog.at_level("WARNING"):
            learner.apply_gradients(grads)
        assert "nan/inf" in caplog.text
        assert torch.isfinite(params[bad].grad).all() and (params[bad].grad[..., 0] == 0).all()
        assert all(torch.isfinite(p).all() for p in params.values())
        assert all(not torch.equal(before[pid], p) for pid, p in params.items())  # all stepped
        caplog.clear()
        learner.apply_gradients({pid: torch.full_like(p, 0.5) for pid, p in params.items()})
        assert "nan/inf" not in caplog.text
    finally:
        algo.stop()
