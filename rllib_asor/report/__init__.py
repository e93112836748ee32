"""Reports from Tune results, and statistics over seeds shared with the benchmarks.

- `results`: trial folders, their rows and params, method labels (`find_trials`);
- `summary`: per (env, method) final values and statistics (`summarize`);
- `render`: report.md, summary.json and PNG curves (`make_report`; `rllib report`);
- `stats`: the one `bootstrap_ci`, `iqm`, `mean_std` (also used by benchmarks/).
"""
