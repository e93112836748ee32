"""`PairedStudy`'s readings beside the rule: the declining seeds of the named methods and a
descriptive paired difference against another study's runs (race_scale_2m's and
race_scale_rollout_2m's summaries), shown after the rule's table."""

from pathlib import Path

from studies.lib.paired_verdict import PairedStudy
from studies.lib.run_files import run_file, write_run

PEAKED_THEN_LOW = [[125_000 * (i + 1), 0.7 if i < 8 else 0.1, 0.0] for i in range(16)]
HOLDS = [[125_000 * (i + 1), 0.7, 0.0] for i in range(16)]


def write(study: Path, method: str, seed: int, success: float, curve: list) -> None:
    record = {
        "method": method,
        "seed": seed,
        "train_wall_s": 10.0,
        "eval": {"per_map": {"0": {"success": success}}},
        "curve": curve,
    }
    write_run(run_file(study / "runs", f"{method}-{seed}"), record)


def test_declining_seeds_and_the_descriptive_pair_follow_the_rule_table(tmp_path: Path) -> None:
    here, other = tmp_path / "mine", tmp_path / "earlier"
    for seed in range(4):
        write(here, "new", seed, 0.5 + 0.1 * seed, PEAKED_THEN_LOW if seed == 2 else HOLDS)
        write(other, "old", seed, 0.4 + 0.1 * seed, HOLDS)
    study = PairedStudy(
        arms=("new",),
        baseline="old",
        also=("earlier",),
        declining=(("", "new"), ("earlier", "old")),
        beside=("earlier", "old", "new"),
    )
    res = study.summarise(here / "runs")
    assert res["declining"] == {"new": {"runs": 4, "seeds": [2]}, "old": {"runs": 4, "seeds": []}}
    pair = res["new_vs_500k"]
    assert pair["pairs"] == 4 and abs(pair["diff_mean"] - 0.1) < 1e-9
    text = study.table(res)
    assert text.index("Verdict for new") < text.index("| new | 4 | 1 | 2 |")
    assert "| old | 4 | 0 | – |" in text
    assert "new − old (500k), descriptive: 4 pairs, +0.100" in text and text.endswith("\n")
    # without them, the rule's table alone
    plain = PairedStudy(arms=("new",), baseline="old", also=("earlier",))
    res = plain.summarise(here / "runs")
    assert "declining" not in res and plain.table(res).endswith("exist)**\n")
