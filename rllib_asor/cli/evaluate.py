"""`rllib evaluate CHECKPOINT`."""

from __future__ import annotations

import argparse


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("checkpoint")
    parser.add_argument("--episodes", type=int, default=10)
    parser.add_argument("--json", action="store_true")


def run(args: argparse.Namespace) -> int:
    return 0
