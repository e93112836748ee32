"""docker/: images, Ray cluster launcher config and KubeRay RayJob are consistent and valid.

No Docker engine or Kubernetes here: the cluster config is checked against Ray's own autoscaler
schema and `ray up`'s config preparation; the rest by parsing the files.
"""

from __future__ import annotations

import copy
import fnmatch
import json
import re
import shlex
import tomllib
from pathlib import Path, PurePosixPath
from typing import Any

import jsonschema
import pytest
import ray
import yaml
from ray.autoscaler._private.util import prepare_config, validate_config

ROOT = Path(__file__).resolve().parents[1]
DOCKER = ROOT / "docker"
VERSION = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["version"]
IMAGE = f"rllib-asor:{VERSION}"
"""Our image's name and tag as the manifests spell it (docs/cluster.md says how to retag)."""
ENTRY_PATTERN = "tuned_examples/race/*.yaml"


def dockerfile(name: str) -> list[str]:
    """Dockerfile instructions with line continuations joined and comments dropped."""
    text = (DOCKER / name).read_text()
    text = re.sub(r"\\\n", " ", text)
    return [
        ln.strip() for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")
    ]


def instructions(name: str, op: str) -> list[str]:
    return [ln.split(None, 1)[1] for ln in dockerfile(name) if ln.split(None, 1)[0].upper() == op]


def pip_install_args(run: str) -> list[str]:
    """Requirement arguments of every `pip install` in a RUN line (options and their values dropped)."""
    out: list[str] = []
    for cmd in run.split("&&"):
        argv = shlex.split(cmd)
        if argv[:2] != ["pip", "install"]:
            continue
        skip = False
        for a in argv[2:]:
            if skip:
                skip = False
            elif a in ("--index-url", "--extra-index-url", "-i", "-c", "-r"):
                skip = True
            elif not a.startswith("-"):
                out.append(a)
    return out


def cluster_config() -> dict[str, Any]:
    return yaml.safe_load((DOCKER / "cluster.yaml").read_text())


def rayjob_docs() -> list[dict[str, Any]]:
    return [d for d in yaml.safe_load_all((DOCKER / "rayjob.yaml").read_text()) if d]


def rayjob() -> dict[str, Any]:
    (job,) = [d for d in rayjob_docs() if d.get("kind") == "RayJob"]
    return job


def image_workdir() -> PurePosixPath:
    (workdir,) = instructions("Dockerfile", "WORKDIR")
    assert instructions("Dockerfile.gpu", "WORKDIR") == [workdir]
    return PurePosixPath(workdir)


# --------------------------------------------------------------------------- Dockerfiles


@pytest.mark.parametrize(
    ("name", "base"),
    [
        ("Dockerfile", "rayproject/ray:2.60.0-py311"),
        ("Dockerfile.gpu", "rayproject/ray:2.60.0-py311-gpu"),
    ],
)
def test_dockerfile_starts_from_ray_image_matching_installed_ray(name: str, base: str) -> None:
    assert instructions(name, "FROM") == [base]
    assert base.split(":")[1].startswith(ray.__version__ + "-")


@pytest.mark.parametrize(
    ("name", "index"), [("Dockerfile", "cpu"), ("Dockerfile.gpu", "${TORCH_CUDA}")]
)
def test_dockerfile_pins_torch_from_pytorch_index_before_installing_project(
    name: str, index: str
) -> None:
    runs = instructions(name, "RUN")
    torch_i = next(i for i, r in enumerate(runs) if "torch==2.13.0" in r)
    assert f"--index-url https://download.pytorch.org/whl/{index} torch==2.13.0" in runs[torch_i]
    project_i = next(i for i, r in enumerate(runs) if re.search(r"pip install \.(\s|$)", r))
    assert torch_i < project_i
    # Every torch that pip installs is pinned (an open requirement pulls the multi-GB CUDA build).
    torch_args = [a for r in runs for a in pip_install_args(r) if re.match(r"torch\b", a)]
    assert torch_args == ["torch==2.13.0"]
    torch_pin = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["dependencies"]
    assert "torch==2.13.0" in torch_pin


def test_gpu_image_torch_index_is_cuda() -> None:
    (arg,) = [a for a in instructions("Dockerfile.gpu", "ARG") if a.startswith("TORCH_CUDA=")]
    assert re.fullmatch(r"TORCH_CUDA=cu\d{3}", arg)


def test_dockerfiles_copy_project_into_workdir_as_ray_user() -> None:
    for name in ("Dockerfile", "Dockerfile.gpu"):
        lines = dockerfile(name)
        users = [ln.split()[1] for ln in lines if ln.startswith("USER ")]
        assert users[-1] == "ray", "the Ray images expect to run as user ray"
        assert "COPY --chown=ray:users . ." in lines


def test_dockerignore_excludes_local_state_but_not_the_project() -> None:
    patterns = [
        p.strip()
        for p in (ROOT / ".dockerignore").read_text().splitlines()
        if p.strip() and not p.startswith("#")
    ]

    def ignored(path: str) -> bool:
        return any(
            fnmatch.fnmatch(path, p)
            or fnmatch.fnmatch(path.split("/")[0], p)
            or fnmatch.fnmatch(path, p + "/*")
            for p in patterns
        )

    for path in (
        ".venv/bin/python",
        ".git/HEAD",
        "results/x/result.json",
        "rllib_asor/__pycache__/x.pyc",
        "rllib_asor.egg-info/PKG-INFO",
    ):
        assert ignored(path), path
    for path in (
        "pyproject.toml",
        "README.md",
        "rllib_asor/cli/report.py",
        "game_env/__init__.py",
        "tuned_examples/race/ppo-asor.yaml",
        "docker/Dockerfile",
    ):
        assert not ignored(path), path


# --------------------------------------------------------------------------- ray up config


def test_cluster_yaml_validates_against_ray_autoscaler_schema() -> None:
    schema_path = Path(ray.autoscaler.__file__).parent / "ray-schema.json"
    schema = json.loads(schema_path.read_text())
    config = cluster_config()
    jsonschema.validate(config, schema)
    validate_config(config)


def test_cluster_yaml_survives_ray_up_preparation() -> None:
    """`ray up` merges the provider defaults, checks docker and node types, then validates."""
    prepared = prepare_config(copy.deepcopy(cluster_config()))
    validate_config(prepared)
    assert prepared["head_node_type"] in prepared["available_node_types"]
    assert prepared["available_node_types"][prepared["head_node_type"]]["max_workers"] == 0


def test_cluster_yaml_runs_our_image_with_head_and_workers() -> None:
    config = cluster_config()
    assert config["docker"]["image"] == IMAGE
    assert config["docker"]["container_name"]
    types = config["available_node_types"]
    assert config["head_node_type"] in types
    workers = [t for t in types if t != config["head_node_type"]]
    assert workers and all(types[w].get("max_workers", 0) > 0 for w in workers)
    assert any("ray start --head" in c for c in config["head_start_ray_commands"])
    assert any(
        "ray start --address=$RAY_HEAD_IP:6379" in c for c in config["worker_start_ray_commands"]
    )
    assert any("import rllib_asor" in c for c in config["setup_commands"])


# --------------------------------------------------------------------------- KubeRay RayJob


def test_rayjob_has_required_fields() -> None:
    job = rayjob()
    assert job["apiVersion"] == "ray.io/v1"
    assert job["kind"] == "RayJob"
    assert re.fullmatch(r"[a-z0-9]([-a-z0-9]*[a-z0-9])?", job["metadata"]["name"])
    spec = job["spec"]
    assert spec["entrypoint"].startswith("rllib train ")
    cluster = spec["rayClusterSpec"]
    assert cluster["rayVersion"] == ray.__version__
    assert cluster["headGroupSpec"]["template"]["spec"]["containers"]
    assert cluster["workerGroupSpecs"]


def pod_specs() -> list[dict[str, Any]]:
    cluster = rayjob()["spec"]["rayClusterSpec"]
    groups = [cluster["headGroupSpec"], *cluster["workerGroupSpecs"]]
    return [g["template"]["spec"] for g in groups]


def test_rayjob_every_ray_container_uses_our_image_with_resources() -> None:
    for pod in pod_specs():
        (container,) = pod["containers"]
        assert container["image"] == IMAGE
        res = container["resources"]
        assert res["requests"]["cpu"] and res["requests"]["memory"]
        assert res["limits"]["memory"] == res["requests"]["memory"]
        volumes = {v["name"] for v in pod.get("volumes", [])}
        assert {m["name"] for m in container.get("volumeMounts", [])} <= volumes


def test_rayjob_worker_groups_replicas_within_bounds() -> None:
    for group in rayjob()["spec"]["rayClusterSpec"]["workerGroupSpecs"]:
        assert group["groupName"]
        assert group["minReplicas"] <= group["replicas"] <= group["maxReplicas"]


def test_rayjob_results_volume_is_the_shared_claim_in_the_manifest() -> None:
    claims = {
        d["metadata"]["name"]: d for d in rayjob_docs() if d["kind"] == "PersistentVolumeClaim"
    }
    for pod in pod_specs():
        (vol,) = [v for v in pod["volumes"] if "persistentVolumeClaim" in v]
        claim = claims[vol["persistentVolumeClaim"]["claimName"]]
        assert "ReadWriteMany" in claim["spec"]["accessModes"]
        (mount,) = [m for m in pod["containers"][0]["volumeMounts"] if m["name"] == vol["name"]]
        assert mount["mountPath"] == "/home/ray/ray_results"  # Tune's default ~/ray_results


def test_rayjob_entrypoint_names_a_race_yaml_inside_the_image() -> None:
    argv = shlex.split(rayjob()["spec"]["entrypoint"])
    assert argv[:3] == ["rllib", "train", "file"]
    path = PurePosixPath(argv[3])
    rel = path.relative_to(image_workdir()) if path.is_absolute() else path
    assert fnmatch.fnmatch(str(rel), ENTRY_PATTERN), rel
    assert argv[4:] == ["--address", "auto"]
    local = ROOT / rel
    assert local.exists(), f"the RayJob runs {rel}, which is not in the repository"
    experiments = yaml.safe_load(local.read_text())
    assert isinstance(experiments, dict) and experiments
    assert all("run" in exp for exp in experiments.values())


def test_pyproject_declares_the_rllib_console_script() -> None:
    scripts = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]
    assert scripts["rllib"] == "rllib_asor.cli.main:main"
