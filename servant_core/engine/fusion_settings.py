"""The fusion windows of the user's settings, and a policy taking new ones."""

from __future__ import annotations

from typing import Any

from servant_core.fusion import FusionConfig, FusionPolicy, LearnedFusion


def fusion_config(settings: Any) -> FusionConfig:
    """The fusion windows of the user's settings (`servant_core.settings.Settings`)."""
    return FusionConfig(
        acoustic_window_s=settings.acoustic_window_s,
        confirm_window_s=settings.confirm_window_s,
        pictures_needed=settings.pictures_needed,
        picture_interval_s=settings.picture_interval_s,
    )


def reconfigured(policy: FusionPolicy, config: FusionConfig) -> FusionPolicy:
    """`policy` on the windows `config` (a policy of `servant_core.fusion`): itself when they are
    unchanged, so the current window stays open; a fresh one of its kind otherwise, a learned
    policy keeping the net it learned."""
    if policy.config == config:
        return policy
    if isinstance(policy, LearnedFusion):
        return LearnedFusion(config, policy.net)
    kind: Any = type(policy)
    return kind(config)  # type: ignore[no-any-return]
