"""Where a module's tensors live, so that inputs can be made there (torch only)."""

from __future__ import annotations

from typing import Any

import torch
from torch import nn


def module_device(module: Any) -> torch.device:
    """The device of `module`'s first parameter or buffer (the CPU for a module without any, or
    an object that is no `nn.Module`): where its inputs must go before a forward pass."""
    if isinstance(module, nn.Module):
        for tensor in module.parameters():
            return tensor.device
        for tensor in module.buffers():
            return tensor.device
    return torch.device("cpu")
