"""The ASOR method itself: partition, discriminator, visitation proxies, reward. No ray here."""

from rllib_asor.asor.config import AsorConfig
from rllib_asor.asor.partition import partition

__all__ = ["AsorConfig", "partition"]
