"""DARA on a dataset: train the domain classifiers on its parts, write relabelled copies.

The parts are the `rllib data collect` layout `.../<task>/<dynamics>/<quality>` (parquet rows,
column `item` = a msgpack'd `SingleAgentEpisode` state, rllib_asor/data/format.py). Parts of
`target_dynamics` are the target domain, the others the source; every source step's reward
becomes r + η·Δr(s, a, s′) (classifiers.delta_reward), target steps keep theirs. The copies keep
the layout (and the task's manifest.json, so evaluation finds its reference returns) under
`<cache>/<key>/`, keyed by the parts' bytes, the settings and the seed: a second run (a restored
checkpoint, the paired run) reuses them. Offline data is fixed, so the classifiers are trained
once before the rewards are relabelled (DARC, online, trains them along with SAC).
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch

from rllib_asor.algorithms.dara.classifiers import DomainClassifiers, classifier_loss, delta_reward
from rllib_asor.algorithms.dara.settings import DaraSettings

INFO = "dara.json"
"""What a relabelled copy records beside its parts (settings, classifier statistics)."""


def transitions(episodes: list[tuple[np.ndarray, ...]]) -> tuple[np.ndarray, ...]:
    """(s, a, s′) of every step of `episodes` (read_part's tuples), concatenated."""
    obs = np.concatenate([e[0][:-1] for e in episodes])
    actions = np.concatenate([e[1] for e in episodes])
    next_obs = np.concatenate([e[0][1:] for e in episodes])
    return obs, actions, next_obs


def train_classifiers(
    source: tuple[np.ndarray, ...],
    target: tuple[np.ndarray, ...],
    settings: DaraSettings,
    seed: int,
) -> tuple[DomainClassifiers, dict[str, float]]:
    """DARC's classifier pair trained for `classifier_steps` Adam steps on balanced batches
    (`batch_size` rows of each domain); statistics on all rows at the end (no noise). On the
    CPU: a one-off relabelling of the offline data before training, not the Learner's work."""
    rng = np.random.default_rng(seed)
    with torch.random.fork_rng():
        torch.manual_seed(seed)
        model = DomainClassifiers(
            source[0].shape[1], source[1].shape[1], settings.hidden, settings.input_noise
        )
        opt = torch.optim.Adam(model.parameters(), lr=settings.lr)
        src = [torch.as_tensor(x, dtype=torch.float32, device="cpu") for x in source]
        tgt = [torch.as_tensor(x, dtype=torch.float32, device="cpu") for x in target]
        for _ in range(settings.classifier_steps):
            i = torch.as_tensor(rng.integers(0, len(src[0]), settings.batch_size), device="cpu")
            j = torch.as_tensor(rng.integers(0, len(tgt[0]), settings.batch_size), device="cpu")
            loss, _ = classifier_loss(
                model, tuple(x[i] for x in src), tuple(x[j] for x in tgt), noisy=True
            )
            opt.zero_grad()
            loss.backward()
            opt.step()
        _, stats = classifier_loss(model, tuple(src), tuple(tgt), noisy=False)
    return model, stats


def dara_parts(
    paths: Sequence[str], settings: DaraSettings | dict[str, Any], seed: int = 0
) -> tuple[list[str], dict[str, float]]:
    """The relabelled copies of the parts `paths` (same order) and DARA's statistics
    (classifier losses and accuracies, Δr of the source steps); made once per key."""
    from rllib_asor.algorithms.maple.data import read_part
    from rllib_asor.algorithms.maple.ensemble import dataset_key

    s = settings if isinstance(settings, DaraSettings) else DaraSettings.from_dict(settings)
    paths = [str(Path(p)) for p in paths]
    dyns = [Path(p).parent.name for p in paths]
    if s.target_dynamics not in dyns:
        raise ValueError(
            f"dara.target_dynamics={s.target_dynamics!r} is invalid: allowed the dynamics of a "
            f"dataset part ({' | '.join(dict.fromkeys(dyns))})"
        )
    if all(d == s.target_dynamics for d in dyns):
        raise ValueError(
            f"dara.target_dynamics={s.target_dynamics!r}: every dataset part is of that dynamics; "
            "DARA needs source parts of other dynamics too"
        )
    key = dataset_key(paths, s.to_dict(), extra=f"dara-seed{seed}")
    root = Path(os.path.expanduser(s.cache)) if s.cache else Path(tempfile.gettempdir()) / "dara"
    out_dir = root / key
    new = [
        str(out_dir / Path(p).parent.parent.name / Path(p).parent.name / Path(p).name)
        for p in paths
    ]
    info_file = out_dir / INFO
    if info_file.is_file():
        info = json.loads(info_file.read_text())
        return new, {**info["stats"], "cached": 1.0}
    t0 = time.perf_counter()
    parts = [read_part(p) for p in paths]
    target = [e for p, d in zip(parts, dyns, strict=True) if d == s.target_dynamics for e in p]
    source = [e for p, d in zip(parts, dyns, strict=True) if d != s.target_dynamics for e in p]
    model, stats = train_classifiers(transitions(source), transitions(target), s, seed)
    deltas = []
    tmp = Path(tempfile.mkdtemp(prefix=f".{key}.tmp-", dir=_mkdir(root)))
    try:
        for path, dyn, episodes, dest in zip(paths, dyns, parts, new, strict=True):
            d = None if dyn == s.target_dynamics else _episode_deltas(model, episodes, s.delta_clip)
            if d is not None:
                deltas += list(np.concatenate(d)) if d else []
            _write_part(Path(path), tmp / Path(dest).relative_to(out_dir), d, s.eta)
            manifest = Path(path).parent.parent / "manifest.json"
            copy = tmp / Path(dest).relative_to(out_dir).parent.parent / "manifest.json"
            if manifest.is_file() and not copy.is_file():
                shutil.copyfile(manifest, copy)
        arr = np.asarray(deltas, dtype=np.float64)
        stats.update(
            {
                "delta_r_mean": float(arr.mean()) if arr.size else 0.0,
                "delta_r_min": float(arr.min()) if arr.size else 0.0,
                "delta_r_max": float(arr.max()) if arr.size else 0.0,
                "source_steps": float(arr.size),
                "seconds": time.perf_counter() - t0,
            }
        )
        state = {k: v.tolist() for k, v in model.state_dict().items()}
        (tmp / INFO).write_text(
            json.dumps(
                {"settings": s.to_dict(), "seed": seed, "stats": stats, "classifiers": state}
            )
        )
        try:
            os.replace(tmp, out_dir)  # atomic: a parallel run that finished first wins
        except OSError:
            shutil.rmtree(tmp, ignore_errors=True)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return new, {**stats, "cached": 0.0}


def load_classifiers(relabelled_part: str) -> DomainClassifiers:
    """The classifiers a relabelled copy was made with (from its `dara.json`)."""
    info = json.loads((Path(relabelled_part).parent.parent.parent / INFO).read_text())
    s = DaraSettings.from_dict(info["settings"])
    state = {k: torch.as_tensor(v, device="cpu") for k, v in info["classifiers"].items()}
    obs_dim = state["advantage.0.weight"].shape[1] - state["sa.0.weight"].shape[1]
    model = DomainClassifiers(
        obs_dim, state["sa.0.weight"].shape[1] - obs_dim, s.hidden, s.input_noise
    )
    model.load_state_dict(state)
    return model


def _mkdir(path: Path) -> Path:
    path.mkdir(parents=True, exist_ok=True)
    return path


def _episode_deltas(
    model: DomainClassifiers, episodes: list[tuple[np.ndarray, ...]], clip: float
) -> list[np.ndarray]:
    """Δr of every step of each episode."""
    out = []
    for obs, actions, _, _ in episodes:
        o = torch.tensor(obs, dtype=torch.float32, device="cpu")
        a = torch.tensor(actions, dtype=torch.float32, device="cpu")
        out.append(delta_reward(model, o[:-1], a, o[1:], clip).cpu().numpy())
    return out


def _write_part(src: Path, dest: Path, deltas: list[np.ndarray] | None, eta: float) -> None:
    """Copy one part, adding η·Δr to each episode's rewards (None: copy unchanged). Episodes
    without actions (which `read_part` skips) are copied unchanged."""
    import msgpack
    import msgpack_numpy as mnp
    import pyarrow as pa
    import pyarrow.parquet as pq

    dest.mkdir(parents=True, exist_ok=True)
    k = 0
    for n, file in enumerate(sorted(src.glob("*.parquet"))):
        rows = []
        for raw in pq.read_table(file).column("item").to_pylist():
            if deltas is None:
                rows.append(raw)
                continue
            state = msgpack.unpackb(raw, object_hook=mnp.decode)
            rew = state["rewards"]
            data = np.array(rew["data"], dtype=np.float64)
            steps = len(data) - int(rew.get("lookback", 0) or 0)
            if steps <= 0:
                rows.append(raw)
                continue
            data[len(data) - steps :] += eta * deltas[k].astype(np.float64)
            k += 1
            rew["data"] = data if isinstance(rew["data"], np.ndarray) else data.tolist()
            rows.append(msgpack.packb(state, default=mnp.encode))
        table = pa.table({"item": pa.array(rows, type=pa.binary())})
        pq.write_table(table, (dest / f"part-{n:05d}.parquet").as_posix())
