"""Reporting: statistics over seeds (`stats`), shared by `rllib report` and the benchmarks."""
