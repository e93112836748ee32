"""benchmarks.scaling's arguments and benchmarks.gpu_check_summary's verdicts (no Ray, no
training): bad input is one line naming the flag, runner counts are cut to the machine, and
the GPU targets are judged only on CUDA results."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import pytest

from benchmarks import gpu_check_summary as summary
from benchmarks import scaling

ROOT = Path(__file__).resolve().parents[2]


def test_runner_counts_are_cut_to_the_cpus_the_machine_has() -> None:
    assert scaling.parse_runners("1,2,4,8,14", cpus=2) == [1, 2]
    assert scaling.parse_runners("1,2,4,8,14", cpus=16) == [1, 2, 4, 8, 14]
    assert scaling.parse_runners("4", cpus=2) == [1]  # nothing fits: one runner


@pytest.mark.parametrize("text", ["", "0", "1,x", "-2", "1,,0"])
def test_bad_runner_counts_name_the_flag(text: str) -> None:
    with pytest.raises(ValueError, match=r"--runners .* allowed positive integers"):
        scaling.parse_runners(text, cpus=4)


def test_bad_input_is_one_line_and_exit_2(capsys: pytest.CaptureFixture[str]) -> None:
    assert scaling.main(["--device", "gpu"]) == 2
    err = capsys.readouterr().err.strip()
    assert err == "scaling: --device 'gpu' is invalid: allowed cpu or cuda"
    assert scaling.main(["--parts", "learner,train"]) == 2
    assert "--parts 'learner,train' is invalid: allowed a comma list of learner" in (
        capsys.readouterr().err
    )
    assert scaling.main(["--epochs", "0"]) == 2
    assert "--epochs 0 is invalid" in capsys.readouterr().err


def test_quick_settles_small_defaults_and_flags_override_them() -> None:
    args = scaling.settle(scaling.build_parser().parse_args(["--quick", "--runners", "1,2"]))
    assert (args.record_batches, args.learner_passes, args.iters, args.trials) == (3, 1, 2, 2)
    assert args.algo_list == ["ppo", "asor"] and args.part_list == list(scaling.PARTS)
    args = scaling.settle(scaling.build_parser().parse_args(["--quick", "--iters", "7"]))
    assert args.iters == 7


def scaling_json(device: str, e2e: dict[tuple[str, int], float], learner: float) -> dict:
    rows = [
        {"algo": a, "runners": n, "e2e": v, "learner": learner, "learner_device": device}
        for (a, n), v in e2e.items()
    ]
    return {"machine": "x", "wall_s": 1.0, "settings": {"device": device}, "rows": rows}


def test_targets_are_judged_on_cuda_only() -> None:
    e2e = {("ppo", 1): 1_600.0, ("asor", 1): 1_500.0, ("ppo", 14): 16_500.0,
           ("asor", 14): 14_500.0}  # fmt: skip
    data = scaling_json("cuda", e2e, 12_000.0)
    for row in data["rows"]:
        row["sample"] = {1: 3_100.0, 14: 28_000.0}[row["runners"]]
    rows = {r[0]: r for r in summary.targets(data, None)}
    assert rows["PPO+ASOR end to end, 14 runners (env steps/s)"][1:] == [
        "14,500", "≥ 15,000", "NOT met"]  # fmt: skip
    assert rows["PPO end to end, 14 runners (env steps/s)"][3] == "met"
    assert rows["PPO+ASOR ÷ PPO end to end, 14 runners"][1:] == ["0.88", "≥ 0.9", "NOT met"]
    assert rows["PPO+ASOR end to end, 14 ÷ 1 runners"][1] == "9.67"
    assert rows["sampling only, 1 runner(s) (env steps/s)"][3] == "met"
    assert rows["sampling only, 14 runners (env steps/s)"][3] == "NOT met"
    assert rows["Learner alone, best (env steps/s)"][3] == "met"
    rows = summary.targets(scaling_json("cpu", e2e, 12_000.0), None)
    assert {r[3] for r in rows} == {"not judged (CPU)"}


def test_one_runner_count_shows_no_ratio_of_runner_counts() -> None:
    data = scaling_json("cuda", {("ppo", 14): 6_000.0, ("asor", 14): 5_900.0}, 14_000.0)
    for row in data["rows"]:
        row["sample"] = 12_000.0
    checks = [r[0] for r in summary.targets(data, None)]
    assert "sampling only, 14 runners (env steps/s)" in checks
    assert not any("÷ 14 runners" in c or "runner(s)" in c for c in checks), checks


def test_overlapped_end_to_end_is_judged_beside_the_synchronous_one() -> None:
    sync = scaling_json("cuda", {("ppo", 1): 700.0, ("asor", 1): 800.0, ("ppo", 14): 5_000.0,
                                 ("asor", 14): 4_900.0}, 15_000.0)  # fmt: skip
    over = scaling_json("cuda", {("ppo_overlap", 14): 16_200.0, ("asor_overlap", 14): 14_000.0}, 0)
    rows = {r[0]: r for r in summary.targets(sync, None, over)}
    assert rows["PPO+ASOR overlapped end to end, 14 runners (env steps/s)"][1:] == [
        "14,000", "≥ 15,000", "NOT met"]  # fmt: skip
    assert rows["PPO overlapped end to end, 14 runners (env steps/s)"][3] == "met"
    assert rows["PPO+ASOR ÷ PPO overlapped, 14 runners"][1:] == ["0.86", "≥ 0.9", "NOT met"]
    assert rows["PPO+ASOR end to end, 14 runners (env steps/s)"][3] == "NOT met"  # unchanged
    assert not any("overlapped" in r[0] for r in summary.targets(sync, None))


def test_sampling_at_32_envs_per_runner_is_judged_on_the_sampling_targets() -> None:
    envs32 = scaling_json("cuda", {("ppo", 1): 0.0, ("ppo", 14): 0.0}, 0.0)
    for row in envs32["rows"]:
        row["sample"] = {1: 3_200.0, 14: 25_000.0}[row["runners"]]
    rows = {r[0]: r for r in summary.targets(None, None, None, envs32)}
    assert rows["sampling only, 32 envs per runner, 1 runner(s) (env steps/s)"][1:] == [
        "3,200", "≥ 3,000", "met"]  # fmt: skip
    assert rows["sampling only, 32 envs per runner, 14 runner(s) (env steps/s)"][3] == "NOT met"


def test_overlap_names_build_overlapped_ppo_with_or_without_asor() -> None:
    from rllib_asor.algorithms.ppo.overlap import OverlappedPPO, overlap_enabled

    args = scaling.settle(
        scaling.build_parser().parse_args(["--quick", "--algos", "ppo_overlap,asor_overlap"])
    )
    plain, asor = (scaling.race_config(a, args, 1) for a in ("ppo_overlap", "asor_overlap"))
    assert plain.algo_class is OverlappedPPO and overlap_enabled(plain) and overlap_enabled(asor)
    assert "asor" not in (plain.learner_config_dict or {}) and "asor" in asor.learner_config_dict
    assert scaling.race_config("ppo", args, 1).algo_class is not OverlappedPPO


def test_test_counts_read_pytests_junit_report(tmp_path: Path) -> None:
    xml = tmp_path / "r.xml"
    assert summary.test_counts(xml).startswith("no report")
    xml.write_text(
        '<testsuites><testsuite tests="9" failures="1" errors="0" skipped="5"/></testsuites>'
    )
    assert summary.test_counts(xml) == "passed 3, failed 1, skipped 5"


def test_summary_says_what_is_missing(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "e2e").mkdir()
    e2e = {("ppo", 1): 300.0, ("asor", 1): 250.0}
    (tmp_path / "e2e" / "scaling.json").write_text(json.dumps(scaling_json("cpu", e2e, 500.0)))
    assert summary.main([str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "| scaling benchmark, Learner alone | no result (see its log) |" in out
    assert "| PPO+ASOR, 1 runner(s) (env steps/s) | e2e 250; learner 500 |" in out
    assert "one runner's split: no result (see runner.log)" in out


def test_gpu_check_script_parses() -> None:
    subprocess.run(["bash", "-n", str(ROOT / "scripts/gpu_check.sh")], check=True)


def test_cuda_without_a_gpu_is_refused_in_one_line(capsys: pytest.CaptureFixture[str]) -> None:
    torch = pytest.importorskip("torch")
    if torch.cuda.is_available():
        pytest.skip("this machine has CUDA")
    assert scaling.main(["--device", "cuda", "--out", "/nonexistent/never-written"]) == 2
    assert capsys.readouterr().err.strip() == (
        "scaling: --device 'cuda' is invalid here: torch sees no CUDA device; allowed cpu"
    )


@pytest.mark.parametrize(
    ("flags", "message"),
    [
        (["--torch-compile", "fast"], "--torch-compile 'fast' is invalid: allowed off, default"),
        (["--torch-compile", "default", "--compile-backend", "tvm"],
         "--compile-backend 'tvm' is invalid: allowed inductor, cudagraphs, aot_eager"),
        (["--torch-compile", "default", "--compile-backend", "cudagraphs"],
         "--compile-backend cudagraphs is invalid here: allowed with --device cuda"),
    ],
)  # fmt: skip
def test_bad_compile_settings_are_one_line(
    flags: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert scaling.main(flags) == 2
    assert message in capsys.readouterr().err


def test_a_compiled_learner_is_configured_and_its_mode_goes_to_inductor_only() -> None:
    def config(*flags: str):
        args = scaling.settle(scaling.build_parser().parse_args(["--quick", *flags]))
        return scaling.race_config("asor", args, 1)

    assert not config().torch_compile_learner
    c = config("--torch-compile", "reduce-overhead")
    assert c.torch_compile_learner and c.torch_compile_learner_dynamo_backend == "inductor"
    assert c.torch_compile_learner_dynamo_mode == "reduce-overhead"
    assert str(c.torch_compile_learner_what_to_compile).endswith("complete_update")
    c = config("--torch-compile", "reduce-overhead", "--compile-backend", "aot_eager")
    assert c.torch_compile_learner_dynamo_backend == "aot_eager"
    assert c.torch_compile_learner_dynamo_mode is None


def test_the_compiled_learner_is_shown_beside_the_one_not_compiled() -> None:
    learner = scaling_json("cuda", {("ppo", 14): 0.0, ("asor", 14): 0.0}, 14_000.0)
    compiled = scaling_json("cuda", {("ppo", 14): 0.0, ("asor", 14): 0.0}, 28_000.0)
    compiled["settings"].update(compile_backend="cudagraphs", torch_compile="reduce-overhead")
    for row in compiled["rows"]:
        row["learner_warmup_s"] = 41.0
    rows = summary.compile_rows(learner, compiled)
    assert len(rows) == 2
    assert "compiled (cudagraphs) ÷ not compiled, PPO+ASOR, 14 runner(s)" in rows[1]
    assert "2.00× (28,000 ÷ 14,000); first pass 41 s" in rows[1]
    # without the Learner not compiled: its own rate only; without a compiled run: no rows
    assert "| 28,000; first pass 41 s |" in summary.compile_rows(None, compiled)[0]
    assert summary.compile_rows(learner, None) == []
