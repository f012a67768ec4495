"""House datasets on disk: generation, manifest, lookup.

A dataset is a folder::

    <dir>/manifest.json              name, generator arguments, sha256 of every file
    <dir>/{train,valid,test}/<id>.xml   MJCF scene (agent included)
    <dir>/{train,valid,test}/<id>.json  metadata (:meth:`leaps_mj.world.houses.House.to_json`)
    <dir>/preview/<id>.png           optional top-down pictures (not in the manifest)

House ``i`` of split ``s`` is generated from the seed
``np.random.SeedSequence([seed, SPLITS.index(s), i]).generate_state(1)[0]``,
so splits are disjoint streams, adding houses to a split never changes the
existing ones, and the same arguments always give the same bytes.

Datasets shipped with the repository live under ``houses/<name>`` at the
repository root (``LEAPS_MJ_HOUSES`` overrides that folder).
"""

from __future__ import annotations

import hashlib
import json
import os
import pathlib
import re
from collections.abc import Callable, Collection, Iterable

import numpy as np

from leaps_mj.world import files, houses, rooms

#: The splits of a dataset, in seed-derivation order.
SPLITS = ("train", "valid", "test")
#: Version of the dataset layout and manifest.
DATASET_FORMAT_VERSION = 1
MANIFEST = "manifest.json"
#: The canonical dataset and the arguments that generate it (the generator's
#: current code makes it; ``roomnav-v1``, 200 / 20 / 50 houses of the
#: single-corridor generator, stays as committed data).
CANONICAL = "roomnav-v2"
CANONICAL_COUNTS = {"train": 200, "valid": 30, "test": 100}
CANONICAL_SEED = 0
#: Repository folder holding the shipped datasets.
HOUSES_DIR = rooms.REPO_DIR / "houses"
_ID_RE = re.compile(r"^(train|valid|test)_\d{4,}$")


def _check_split(split: str) -> int:
    try:
        return SPLITS.index(split)
    except ValueError:
        raise ValueError(f"unknown split {split!r}; expected one of {list(SPLITS)}") from None


def house_seed(seed: int, split: str, index: int) -> int:
    """The generator seed of house ``index`` of ``split`` in a dataset of ``seed``.

    Raises:
      ValueError: for an unknown split or a negative seed or index.
    """
    k = _check_split(split)
    if seed < 0 or index < 0:
        raise ValueError(f"seed and index must be >= 0, got seed={seed}, index={index}")
    return int(np.random.SeedSequence([int(seed), k, int(index)]).generate_state(1)[0])


def house_id(split: str, index: int) -> str:
    """The id (and file stem) of house ``index`` of ``split``: ``train_0007``."""
    _check_split(split)
    return f"{split}_{index:04d}"


def house_json_text(house: houses.House) -> str:
    """The JSON text written beside the MJCF (deterministic)."""
    return json.dumps(house.to_json(), indent=1, sort_keys=True) + "\n"


def build_house(seed: int, split: str, index: int) -> tuple[houses.House, str, str]:
    """Generates one house of a dataset and checks that MuJoCo compiles it.

    Returns:
      (house, MJCF text, JSON text).

    Raises:
      RuntimeError: if the generator gives up or MuJoCo rejects the scene.
    """
    import mujoco

    from leaps_mj.world import generator, mjcf

    hid = house_id(split, index)
    house = generator.generate(house_seed(seed, split, index), hid)
    xml = mjcf.to_xml(house)
    try:
        mujoco.MjModel.from_xml_string(xml)
    except ValueError as e:
        raise RuntimeError(f"house {hid}: MuJoCo rejects the generated scene: {e}") from e
    return house, xml, house_json_text(house)


def sha256_bytes(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def sha256_file(path: str | os.PathLike) -> str:
    return sha256_bytes(pathlib.Path(path).read_bytes())


def _job(args):
    """One house, for a worker: returns the file texts (and writes its preview)."""
    seed, split, index, preview_dir = args
    house, xml, js = build_house(seed, split, index)
    if preview_dir is not None:
        from leaps_mj.world import topdown

        topdown.preview(house, pathlib.Path(preview_dir) / f"{house.id}.png")
    return split, house.id, xml, js


def validate_counts(counts: dict[str, int]) -> dict[str, int]:
    """Checks split counts: known splits, non-negative integers, not all zero.

    Returns:
      the counts for every split in :data:`SPLITS` order (missing ones 0).

    Raises:
      ValueError: naming the bad split or value.
    """
    for split in counts:
        _check_split(split)
    out = {}
    for split in SPLITS:
        n = counts.get(split, 0)
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 0:
            raise ValueError(f"count of split {split!r} must be a non-negative integer, got {n!r}")
        out[split] = int(n)
    if not any(out.values()):
        raise ValueError("every split count is 0: nothing to generate")
    return out


def write_dataset(
    out: str | os.PathLike,
    counts: dict[str, int],
    seed: int = 0,
    name: str | None = None,
    preview: Collection[str] = (),
    workers: int = 1,
    progress: bool = True,
    log: Callable[[str], None] | None = None,
) -> dict:
    """Generates a dataset into ``out`` and writes its manifest.

    Houses are generated in order (or by ``workers`` processes, results taken
    in order), each checked to compile with MuJoCo, and written atomically.
    House files of the splits left over from an earlier, larger run are
    removed so the folder matches the manifest.

    Args:
      out: the dataset folder (created if needed).
      counts: houses per split, e.g. ``{"train": 200, "valid": 20, "test": 50}``.
      seed: the dataset seed (>= 0).
      name: dataset name recorded in the manifest (default: the folder name).
      preview: splits whose houses also get a top-down ``preview/<id>.png``
        (for instance ``("test",)``: pictures of every house would be too
        large to commit).
      workers: processes generating houses (1: in this process).
      progress: show a tqdm progress bar.
      log: called with one line per notable event (stale files removed).

    Returns:
      the manifest (also written to ``out/manifest.json``).

    Raises:
      ValueError: for bad arguments (naming them).
      RuntimeError: if a house cannot be generated or compiled.
    """
    counts = validate_counts(counts)
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
    if workers < 1:
        raise ValueError(f"workers must be >= 1, got {workers}")
    out = pathlib.Path(out)
    if out.exists() and not out.is_dir():
        raise ValueError(f"output path {str(out)!r} exists and is not a directory")
    out.mkdir(parents=True, exist_ok=True)
    name = name or out.resolve().name
    preview = tuple(preview)
    for split in preview:
        _check_split(split)
    preview_dir = out / "preview"

    seeds = {s: [house_seed(seed, s, i) for i in range(counts[s])] for s in SPLITS}
    flat = [v for s in SPLITS for v in seeds[s]]
    if len(set(flat)) != len(flat):  # 32-bit seeds: a collision is astronomically rare
        raise RuntimeError(f"dataset seed {seed} gives two houses the same generator seed")
    jobs = [(seed, s, i, str(preview_dir) if s in preview else None)
            for s in SPLITS for i in range(counts[s])]

    digests: dict[str, str] = {}
    results: Iterable
    pool = None
    if workers > 1 and len(jobs) > 1:
        import multiprocessing

        pool = multiprocessing.get_context("spawn").Pool(min(workers, len(jobs)))
        results = pool.imap(_job, jobs, chunksize=max(1, len(jobs) // (8 * workers)))
    else:
        results = map(_job, jobs)
    try:
        if progress:
            from tqdm import tqdm

            results = tqdm(results, total=len(jobs), desc=f"houses -> {out}", unit="house")
        for split, hid, xml, js in results:
            for ext, text in (("xml", xml), ("json", js)):
                rel = f"{split}/{hid}.{ext}"
                data = text.encode()
                files.write_atomic(out / rel, data)
                digests[rel] = sha256_bytes(data)
    finally:
        if pool is not None:
            pool.terminate()
            pool.join()

    stale = _stale_files(out, counts, preview)
    for p in stale:
        p.unlink()
    if stale and log:
        log(f"removed {len(stale)} stale house file(s) not in this dataset from {out}")

    manifest = {
        "dataset": name,
        "format_version": DATASET_FORMAT_VERSION,
        "house_format_version": houses.FORMAT_VERSION,
        "generator": {
            "seed": int(seed),
            "counts": counts,
            "house_seed": "numpy.random.SeedSequence([seed, split_index, i]).generate_state(1)[0]",
            "split_index": {s: k for k, s in enumerate(SPLITS)},
        },
        "splits": {s: {"count": counts[s], "ids": [house_id(s, i) for i in range(counts[s])],
                       "seeds": seeds[s]} for s in SPLITS},
        "files": dict(sorted(digests.items())),
    }
    files.write_atomic(out / MANIFEST, (json.dumps(manifest, indent=1) + "\n").encode())
    return manifest


def _stale_files(out: pathlib.Path, counts: dict[str, int], preview: tuple[str, ...]) -> list[pathlib.Path]:
    keep = {house_id(s, i) for s in SPLITS for i in range(counts[s])}
    stale = []
    for s in SPLITS:
        for p in sorted((out / s).glob(f"{s}_*")) if (out / s).is_dir() else []:
            if p.suffix in (".xml", ".json") and _ID_RE.match(p.stem) and p.stem not in keep:
                stale.append(p)
    if preview and (out / "preview").is_dir():
        for p in sorted((out / "preview").glob("*.png")):
            if _ID_RE.match(p.stem) and (p.stem not in keep or p.stem.split("_")[0] not in preview):
                stale.append(p)
    return stale


def read_manifest(dataset: str | os.PathLike) -> dict:
    """The manifest of a dataset (a name under ``houses/`` or a folder).

    Raises:
      ValueError: if the dataset or its manifest is missing or not valid JSON.
    """
    path = dataset_dir(dataset) / MANIFEST
    try:
        data = json.loads(path.read_text())
    except OSError as e:
        raise ValueError(f"cannot read manifest {str(path)!r}: {e.strerror}") from None
    except json.JSONDecodeError as e:
        raise ValueError(f"manifest {str(path)!r} is not valid JSON: {e}") from None
    if not isinstance(data, dict) or "files" not in data or "generator" not in data:
        raise ValueError(f"manifest {str(path)!r} is not a leaps_mj dataset manifest")
    return data


def _houses_root() -> pathlib.Path:
    return pathlib.Path(os.environ.get("LEAPS_MJ_HOUSES", HOUSES_DIR))


def known_datasets() -> list[str]:
    """Names of the datasets under the houses folder (those with a manifest)."""
    root = _houses_root()
    return sorted(p.name for p in root.iterdir() if (p / MANIFEST).is_file()) if root.is_dir() else []


def dataset_dir(dataset: str | os.PathLike) -> pathlib.Path:
    """The folder of a dataset.

    ``dataset`` is a name under the houses folder (``"roomnav-v1"``) or a path
    to a dataset folder.

    Raises:
      ValueError: if there is no such folder, naming the known datasets.
    """
    p = pathlib.Path(dataset)
    if len(p.parts) == 1 and (_houses_root() / p).is_dir():
        return _houses_root() / p
    if p.is_dir():
        return p
    raise ValueError(
        f"no house dataset {str(dataset)!r} (looked for a folder of that path and under "
        f"{str(_houses_root())!r}); known datasets: {known_datasets()}"
    )


def list_houses(dataset: str | os.PathLike, split: str) -> list[pathlib.Path]:
    """The house JSON files of one split, sorted by id.

    Raises:
      ValueError: for an unknown split, a missing dataset or an empty split.
    """
    _check_split(split)
    d = dataset_dir(dataset) / split
    paths = sorted(d.glob("*.json")) if d.is_dir() else []
    if not paths:
        present = [s for s in SPLITS if any((dataset_dir(dataset) / s).glob("*.json"))]
        raise ValueError(f"dataset {str(dataset)!r} has no houses in split {split!r}; splits with houses: {present}")
    return paths


def load_houses(dataset: str | os.PathLike, split: str) -> list[houses.House]:
    """Every house of one split (see :func:`list_houses`)."""
    return [houses.House.load(p) for p in list_houses(dataset, split)]


def verify(dataset: str | os.PathLike) -> list[str]:
    """Files whose sha256 differs from the manifest, or that are missing.

    Returns:
      one line per problem (empty when the dataset matches its manifest).
    """
    d = dataset_dir(dataset)
    problems = []
    for rel, digest in read_manifest(d)["files"].items():
        p = d / rel
        if not p.is_file():
            problems.append(f"{rel}: missing")
        elif sha256_file(p) != digest:
            problems.append(f"{rel}: sha256 differs from the manifest")
    return problems
