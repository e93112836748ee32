"""Cross-dynamics benchmark environments. Their gymnasium ids (`rllib_asor.registry.envs.ENV_IDS`)
are registered when `rllib_asor` is imported, so before any module here.

Depends on nothing else of ours (DESIGN.md).
"""
