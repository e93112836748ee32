"""Env-to-module piece: the context encoder's window for the acting policy.

RLlib 2.60's SAC module is stateless ("SAC does not support RNNs, yet"), so instead of a
hidden state the env runner hands the module the last H steps of (s, a_{t−1}) of each episode,
zero-filled before the episode start, as ESCP's inference does
(`Policy.inference_rnn_fix_one_action`, `Policy.inference_one_step`). The episodes need a
lookback of H steps across chunk boundaries (`episode_lookback_horizon`, set by EscpConfig).
"""

from __future__ import annotations

from typing import Any

from ray.rllib.connectors.connector_v2 import ConnectorV2

from rllib_asor.algorithms.escp.replay import WINDOW
from rllib_asor.algorithms.escp.windows import episode_window


class EscpWindowToBatch(ConnectorV2):
    """Adds `batch["escp_window"]` ([H, obs_dim + act_dim] per acting episode)."""

    def __init__(
        self,
        input_observation_space=None,
        input_action_space=None,
        *,
        history_len=16,
        **kwargs: Any,
    ) -> None:
        super().__init__(input_observation_space, input_action_space, **kwargs)
        self.history_len = int(history_len)

    def __call__(self, *, rl_module: Any, batch: dict, episodes: Any, **kwargs: Any) -> Any:
        for episode in self.single_agent_episode_iterator(episodes, agents_that_stepped_only=True):
            self.add_batch_item(
                batch,
                WINDOW,
                item_to_add=episode_window(episode, self.history_len),
                single_agent_episode=episode,
            )
        return batch


class EscpEnvToModule:
    """Picklable `env_to_module_connector` factory: the user's pieces (if any), then ours."""

    def __init__(self, history_len: int, user: Any = None) -> None:
        self.history_len = int(history_len)
        self.user = user

    def __call__(self, env: Any = None, spaces: Any = None, device: Any = None) -> list:
        pieces = []
        if self.user is not None:
            made = self.user(env, spaces, device)
            pieces = list(made) if isinstance(made, (list, tuple)) else [made]
        return [*pieces, EscpWindowToBatch(history_len=self.history_len)]
