"""Chunked, reproducible, crash-safe dataset generation (``nik generate``).

Data flow per chunk: draw uniforms (or Sobol points) for a range of sample indices -> joint
vectors in the sampling ranges (stored dtype) -> branch labels (optional filter) -> FK in
float64 of exactly the stored joints -> append to the ``.npy`` files of a temporary
directory. Memory is bounded by the chunk whatever N is.

Reproducibility: the random stream is cut into fixed blocks of :data:`BLOCK_SIZE` samples;
block ``b`` draws from its own ``torch.Generator`` seeded from ``(seed, b)`` (Sobol: the
scrambled engine for ``seed`` fast-forwarded to the block's start). The chunk size only
decides how many candidates are drawn at once, never which numbers are drawn; FK and
writing always run on the same output blocks (rows ``[k B, (k + 1) B)``), so even a compiled
FK kernel, whose rounding may depend on the batch, sees identical batches. The same
arguments therefore give bit-identical arrays for any chunk size and thread count (tested;
across machines, FK may differ in the last bit with the CPU's math library).

Shards: ``shard=(i, k)`` writes only shard ``i`` of ``k`` of that dataset: the rows of a contiguous
range of whole blocks (:func:`shard_rows`), drawn and computed exactly as the whole run would, so
shards made anywhere (different processes or machines) join with :func:`nik.data.merge_shards`
into the dataset the run without ``shard`` writes, byte for byte except the creation time.
"""

from __future__ import annotations

import datetime as _dt
import math
import os
import sys
from collections import deque
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

import nik
from nik.data.branches import branch_classifier, branch_name
from nik.data.storage import FORMAT_VERSION, AtomicDirectory, NpyStreamWriter, write_meta
from nik.errors import DatasetError
from nik.robots.yamlfile import load_yaml

__all__ = [
    "BLOCK_SIZE",
    "COMPILE_THRESHOLD",
    "Compute",
    "DEFAULT_CHUNK",
    "Sampling",
    "generate_dataset",
    "parse_shard",
    "resolve_ranges",
    "sample_stream",
    "shard_rows",
]

#: Samples per randomness block (part of the reproducibility contract; recorded in meta.json).
BLOCK_SIZE = 65536
#: ``compiled="auto"`` uses the compiled FK kernel from this many samples on.
COMPILE_THRESHOLD = 10_000_000
#: Default samples per chunk (memory: about 1 KB per sample of chunk, i.e. ~260 MB at most).
DEFAULT_CHUNK = 262144
_DTYPES = {"float32": torch.float32, "float64": torch.float64}
_LIMIT_TOL = 1e-9  # rad: a range may exceed a limit by this much (degree round trips)


# ---------------------------------------------------------------------------
# Ranges
# ---------------------------------------------------------------------------
def resolve_ranges(robot, ranges=None) -> tuple[torch.Tensor, str]:
    """Sampling ranges ``(dof, 2)`` float64 radians and a description for the metadata.

    Args:
        ranges: ``None`` or ``"limits"`` (the robot's joint limits); a path to a YAML file
            ``{angles: deg|rad, ranges: [[lo, hi], ...]}`` (one pair per joint; ``angles`` applies to
            revolute joints, prismatic joints' ranges are in metres); or an array ``(dof, 2)`` in
            radians (metres for prismatic joints).

    Raises:
        ValueError: wrong number of joints, lo >= hi, or a range outside the joint limits.
    """
    lim = robot.limits
    if ranges is None or (isinstance(ranges, str) and ranges == "limits"):
        return lim.clone(), "limits"
    if isinstance(ranges, (str, Path)):
        path = Path(ranges)
        if not path.is_file():
            raise FileNotFoundError(f"ranges file not found: {path} (give a YAML file or 'limits')")
        data = load_yaml(path.read_text(), str(path))
        if not isinstance(data, dict) or "ranges" not in data:
            raise ValueError(f"{path}: expected a mapping with 'ranges: [[lo, hi], ...]' and 'angles: deg|rad'")
        unknown = set(data) - {"angles", "ranges", "description", "name", "robot"}
        if unknown:
            raise ValueError(f"{path}: unknown field(s) {sorted(unknown)}; allowed: angles, ranges, description")
        angles = data.get("angles", "rad")
        if angles not in ("deg", "rad"):
            raise ValueError(f"{path}: angles must be 'deg' or 'rad', got {angles!r}")
        values, where, scale = data["ranges"], str(path), (math.pi / 180 if angles == "deg" else 1.0)
    else:
        values, where, scale = ranges, "ranges", 1.0
    try:
        arr = np.asarray(values.tolist() if isinstance(values, torch.Tensor) else values, dtype=float)
    except (TypeError, ValueError) as err:
        raise ValueError(f"{where}: ranges must be a list of [lo, hi] number pairs ({err})") from err
    if arr.ndim != 2 or arr.shape[1] != 2:
        raise ValueError(f"{where}: ranges must be a list of [lo, hi] pairs, got shape {arr.shape}")
    if arr.shape[0] != robot.dof:
        raise ValueError(f"{where}: {arr.shape[0]} ranges for robot {robot.name!r} with {robot.dof} joints")
    if not np.isfinite(arr).all():
        raise ValueError(f"{where}: ranges must be finite numbers")
    prismatic = robot.prismatic.tolist()
    rng = torch.tensor(arr * np.where(prismatic, 1.0, scale)[:, None], dtype=torch.float64)
    for i in range(robot.dof):
        lo, hi = rng[i].tolist()
        llo, lhi = lim[i].tolist()
        show = _mm if prismatic[i] else _deg
        if not lo < hi:
            raise ValueError(f"{where}: joint {i + 1} range [{show(lo)}, {show(hi)}] needs lo < hi")
        if lo < llo - _LIMIT_TOL or hi > lhi + _LIMIT_TOL:
            raise ValueError(
                f"{where}: joint {i + 1} range [{show(lo)}, {show(hi)}] lies outside the joint limits "
                f"[{show(llo)}, {show(lhi)}] of robot {robot.name!r}"
            )
    rng = torch.minimum(torch.maximum(rng, lim[:, :1]), lim[:, 1:])  # absorb the tolerance
    return rng, (str(ranges) if isinstance(ranges, (str, Path)) else "custom")


# ---------------------------------------------------------------------------
# Random streams: numbers depend on (seed, sample index) only
# ---------------------------------------------------------------------------
def _deg(v: float) -> str:
    return f"{math.degrees(v):.6g} deg"


def _mm(v: float) -> str:
    return f"{v * 1e3:.6g} mm"


def _block_seed(seed: int, block: int) -> int:
    """A 63-bit generator seed for block ``block`` of stream ``seed`` (SplitMix via SeedSequence)."""
    return int(
        np.random.SeedSequence([int(seed) & 0xFFFFFFFFFFFFFFFF, int(block)]).generate_state(1, np.uint64)[0]
        >> np.uint64(1)
    )


class _UniformStream:
    """Uniform ``[0, 1)`` float64 numbers ``(m, dof)`` for sample indices ``[start, stop)``."""

    def __init__(self, dof: int, seed: int, block_size: int):
        self.dof, self.seed, self.block_size = dof, seed, block_size
        self._cached: tuple[int, torch.Tensor] | None = None

    def _block(self, b: int) -> torch.Tensor:
        if self._cached is None or self._cached[0] != b:
            g = torch.Generator().manual_seed(_block_seed(self.seed, b))
            self._cached = (b, torch.rand(self.block_size, self.dof, generator=g, dtype=torch.float64))
        return self._cached[1]

    def draw(self, start: int, stop: int) -> torch.Tensor:
        parts, i, B = [], start, self.block_size
        while i < stop:
            b = i // B
            j = min(stop, (b + 1) * B)
            parts.append(self._block(b)[i - b * B : j - b * B])
            i = j
        return parts[0] if len(parts) == 1 else torch.cat(parts)


class _SobolStream:
    """Scrambled Sobol points ``(m, dof)`` in ``[0, 1)`` for indices ``[start, stop)`` (float64)."""

    MAX_POINTS = 2**30

    def __init__(self, dof: int, seed: int):
        self.dof, self.seed = dof, seed
        self._engine = None
        self._pos = 0

    def draw(self, start: int, stop: int) -> torch.Tensor:
        if stop > self.MAX_POINTS:
            raise ValueError(f"the Sobol sampler gives at most 2^30 points, {stop} were asked for")
        if self._engine is None or self._pos != start:
            self._engine = torch.quasirandom.SobolEngine(self.dof, scramble=True, seed=int(self.seed))
            if start:
                self._engine.fast_forward(start)
        self._pos = stop
        return self._engine.draw(stop - start, dtype=torch.float64)


def sample_stream(dof: int, seed: int, sampler: str = "uniform", *, block_size: int = BLOCK_SIZE):
    """The number stream of a sampler: an object whose ``draw(start, stop)`` gives ``(stop - start, dof)``
    float64 numbers in ``[0, 1)`` that depend only on ``(seed, index)``."""
    if sampler == "uniform":
        return _UniformStream(dof, seed, block_size)
    if sampler == "sobol":
        return _SobolStream(dof, seed)
    raise ValueError(f"sampler must be 'uniform' or 'sobol', got {sampler!r}")


def _to_joints(u: torch.Tensor, ranges: torch.Tensor, dtype: torch.dtype) -> torch.Tensor:
    """Map ``u: (m, dof)`` in [0, 1) to joints in ``ranges``, cast to ``dtype`` and kept inside the ranges."""
    lo64, hi64 = ranges[:, 0], ranges[:, 1]
    q = (lo64 + u * (hi64 - lo64)).to(dtype)
    lo, hi = lo64.to(dtype), hi64.to(dtype)
    lo = torch.where(lo.double() < lo64, torch.nextafter(lo, hi), lo)  # a float32 cast may round outward
    hi = torch.where(hi.double() > hi64, torch.nextafter(hi, lo), hi)
    return torch.minimum(torch.maximum(q, lo), hi)


def _flange_meta(robot) -> dict:
    """``{"flange": {"link": NAME, "frame": 4x4}}`` where the robot file names the vendor's flange (panda's
    ``panda_link8``, ur5's ``tool0``; the definition folds it into its tool frame), so that ``nik data info`` names
    the arm's end as ``nik generate`` does; ``{}`` otherwise."""
    flange = getattr(robot, "flange", None)
    if flange is None or getattr(robot, "flange_link", None) is None:
        return {}
    return {"flange": {"link": robot.flange_link, "frame": flange.double().tolist()}}


#: Seconds between the progress lines of a generation whose stderr is not a terminal (a log: no redrawn bar).
PROGRESS_EVERY_S = 10.0


class _ProgressLines:
    """The progress of a generation as lines on stderr (``nik generate panda: 2,000,000 / 10,000,000 samples (20 %),
    12.3 s, about 49 s left``), one every :data:`PROGRESS_EVERY_S` seconds: what ``nik train`` does for a log, in
    place of a tqdm bar, which a file receives as one ever longer line of redraws. A run shorter than that prints
    none. Same ``update`` / ``close`` as the bar."""

    def __init__(self, total: int, desc: str):
        import time

        self.total, self.desc, self.done = int(total), desc, 0
        self._clock = time.perf_counter
        self._t0 = self._last = self._clock()

    def update(self, m: int) -> None:
        self.done += int(m)
        now = self._clock()
        if now - self._last < PROGRESS_EVERY_S or self.done >= self.total:
            return
        self._last = now
        spent = now - self._t0
        left = spent * (self.total - self.done) / max(self.done, 1)
        print(
            f"{self.desc}: {self.done:,} / {self.total:,} samples ({100 * self.done / max(self.total, 1):.0f} %), "
            f"{spent:.1f} s, about {left:.0f} s left",
            file=sys.stderr,
            flush=True,
        )

    def close(self) -> None:
        pass


def _progress(total: int, enabled: bool | None, desc: str):
    try:
        from tqdm.auto import tqdm
    except ImportError:  # pragma: no cover - tqdm is a dependency
        return None
    if enabled is None:
        enabled = sys.stderr.isatty()
        if not enabled:
            return _ProgressLines(total, desc)
    try:
        size = os.get_terminal_size(sys.stderr.fileno())
        ncols, nrows = size.columns or 100, size.lines or 24  # 0 x 0 on a pty without a size: tqdm would hide
    except OSError:
        ncols, nrows = 100, 24
    return tqdm(
        total=total,
        desc=desc,
        unit="sample",
        unit_scale=True,
        disable=not enabled,
        ncols=min(ncols, 120),
        nrows=nrows,
        file=sys.stderr,
    )


def _split_sizes(n: int, val_fraction: float, test_fraction: float) -> dict[str, list[int]]:
    for name, f in (("val_fraction", val_fraction), ("test_fraction", test_fraction)):
        if not isinstance(f, (int, float)) or isinstance(f, bool) or not 0.0 <= f < 1.0:
            raise ValueError(f"{name} must be a number in [0, 1), got {f!r}")
    n_val, n_test = int(round(n * val_fraction)), int(round(n * test_fraction))
    n_train = n - n_val - n_test
    if n_train < 1:
        raise ValueError(
            f"val_fraction + test_fraction = {val_fraction + test_fraction:g} leaves no training samples out of n = {n}"
        )
    return {"train": [0, n_train], "val": [n_train, n_train + n_val], "test": [n_train + n_val, n]}


def parse_shard(shard) -> tuple[int, int]:
    """``"I/N"`` or ``(I, N)`` -> ``(I, N)`` with ``0 <= I < N``; ValueError otherwise."""
    if isinstance(shard, str):
        parts = shard.split("/")
        try:
            shard = tuple(int(p) for p in parts)
        except ValueError:
            shard = ()
        if len(shard) != 2:
            raise ValueError(f"shard must be I/N with integers 0 <= I < N (e.g. 0/4), got {'/'.join(parts)!r}")
    try:
        i, k = (int(v) for v in shard)
    except (TypeError, ValueError):
        raise ValueError(f"shard must be (I, N) or 'I/N' with 0 <= I < N, got {shard!r}") from None
    if not 0 <= i < k:
        raise ValueError(f"shard I/N needs 0 <= I < N (shards are numbered from 0), got {i}/{k}")
    return i, k


def shard_rows(n: int, shard, block_size: int = BLOCK_SIZE) -> tuple[int, int]:
    """Rows ``[start, stop)`` of shard ``(i, k)`` of an ``n``-sample dataset: whole randomness blocks,
    as evenly spread over the ``k`` shards as blocks allow (so FK sees the same batches as in one run).
    With fewer blocks (``ceil(n / block_size)``) than shards, some shards are empty (``start == stop``).
    """
    i, k = parse_shard(shard)
    blocks = -(-int(n) // int(block_size))
    return min(n, i * blocks // k * block_size), min(n, (i + 1) * blocks // k * block_size)


class _BackgroundIO:
    """Runs file writes (and their SHA-256) in one background thread, in submission order.

    ``file.write`` and ``hashlib`` release the GIL on large buffers, so writing block k overlaps
    with sampling and FK of block k + 1: on 2 cores, one does the maths, the other the I/O. At
    most ``depth`` writes are in flight (memory stays bounded); an error in a write is raised
    by the next :meth:`submit` or by :meth:`drain`.
    """

    def __init__(self, depth: int = 3):
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="nik-data-io")
        self._pending: deque = deque()
        self._depth = depth

    def submit(self, fn, *args) -> None:
        while len(self._pending) >= self._depth:
            self._pending.popleft().result()
        self._pending.append(self._pool.submit(fn, *args))

    def drain(self) -> None:
        while self._pending:
            self._pending.popleft().result()
        self._pool.shutdown(wait=True)

    def cancel(self) -> None:
        for f in self._pending:
            f.cancel()
        self._pool.shutdown(wait=True)  # let a running write finish before the files are closed
        self._pending.clear()


# ---------------------------------------------------------------------------
# The generator
# ---------------------------------------------------------------------------
@dataclass(frozen=True)
class Sampling:
    """Which rows :func:`generate_dataset` draws and how it splits them (each field changes the dataset).

    Attributes:
        sampler: ``"uniform"`` (iid uniform in the ranges) or ``"sobol"`` (scrambled Sobol
            sequence from ``torch.quasirandom``, low discrepancy; at most 2^30 points).
        ranges: ``None``/``"limits"`` (joint limits), a YAML ranges file, or ``(dof, 2)`` radians;
            see :func:`resolve_ranges`.
        block_size: samples per randomness block (changes the numbers drawn; keep the default).
        val_fraction, test_fraction: sizes of the validation and test splits (fractions of n,
            rounded). Splits are contiguous row ranges train | val | test; the samples are
            drawn independently of their index, so this is a random split (Sobol: each part
            is itself a spread-out stretch of the sequence).
    """

    sampler: str = "uniform"
    ranges: Any = None
    block_size: int = BLOCK_SIZE
    val_fraction: float = 0.1
    test_fraction: float = 0.1


@dataclass(frozen=True)
class Compute:
    """Where and how :func:`generate_dataset` computes (the dataset does not depend on it beyond FK rounding, which
    ``meta["fk"]`` records).

    Attributes:
        device: where FK runs (``"cpu"``, ``"cuda"``); the random numbers are always drawn on
            the CPU so a dataset does not depend on the device beyond FK rounding.
        chunk_size: samples processed at once; bounds memory (about 1 KB per sample), does not
            change the result.
        compiled: ``True``: run the ``torch.compile``'d FK (compiles once, several seconds; then
            up to 1.2x faster end to end here); ``False``: eager FK; ``"auto"`` (default): compiled when
            ``n >= COMPILE_THRESHOLD`` (10,000,000), where the compile time pays off. Compiled
            and eager FK may differ in the last bit (both are FK to ~1e-16 m), so the choice is
            recorded in ``meta["fk"]``; either way the result is deterministic.
        threads: torch threads for sampling, labels and FK while generating (restored afterwards;
            ``None``: leave torch's setting). Writing and hashing run in one more thread, so the
            default 1 keeps 2 cores busy without oversubscribing them (oversubscribed, torch's
            thread pool slows down several-fold). The result does not depend on it.
    """

    device: Any = "cpu"
    chunk_size: int = DEFAULT_CHUNK
    compiled: bool | str = "auto"
    threads: int | None = 1


def generate_dataset(
    robot,
    n: int,
    out: str | Path,
    *,
    seed: int = 0,
    sampling: Sampling | None = None,
    dtype: str | torch.dtype = "float64",
    branch: int | None = None,
    overwrite: bool = False,
    progress: bool | None = None,
    fsync: bool = True,
    shard=None,
    compute: Compute | None = None,
) -> Path:
    """Generate ``n`` (joint vector, pose) pairs and write them to the directory ``out``.

    Args:
        robot: a :class:`nik.Robot`, a built-in name or a robot file.
        n: number of samples (> 0).
        out: dataset directory to create, e.g. ``data/kuka_kr_1m``.
        seed: random seed; the same arguments give bit-identical arrays.
        sampling: :class:`Sampling`, which rows are drawn and how they are split (default: uniform in the joint
            limits, 10 % validation, 10 % test).
        dtype: ``"float32"`` or ``"float64"``: storage dtype of q and pose. q is drawn in float64,
            rounded to ``dtype`` (and kept inside the ranges); the pose is FK of exactly the
            stored q, computed in float64 and rounded once, so ``FK(stored q) == stored pose`` to
            the storage precision.
        branch: keep only samples of this IK branch label (0..7; see :mod:`nik.data.branches`),
            by rejection until n are kept (deterministic: the first n accepted candidates).
            ValueError for arms without a branch classifier.
        overwrite: replace an existing dataset at ``out`` (the old one is removed only after the
            new one is complete). Without it an existing ``out`` is a FileExistsError.
        progress: show a tqdm progress bar; None (default): a bar when stderr is a terminal, else a progress line
            every :data:`PROGRESS_EVERY_S` seconds; False: nothing.
        fsync: flush files to disk before the final rename.
        shard: ``(i, k)`` or ``"i/k"``: write only shard ``i`` (0-based) of ``k`` of this dataset, the
            rows :func:`shard_rows` gives; join the shards with :func:`nik.data.merge_shards`
            (``nik data merge``). Not with ``branch`` (rejection makes every row depend on all before it).
        compute: :class:`Compute`, where and how it computes (default: FK on the CPU, one torch thread).

    Returns:
        The dataset directory ``out`` (a :class:`pathlib.Path`).

    Raises:
        ValueError (RobotDefinitionError, DatasetError): bad arguments; FileExistsError: ``out``
        exists; PermissionError / NotADirectoryError: the output folder cannot be written.
    """
    from nik.robots import load_robot

    sampling, compute = sampling or Sampling(), compute or Compute()
    if not isinstance(sampling, Sampling) or not isinstance(compute, Compute):
        name, got = ("sampling", sampling) if not isinstance(sampling, Sampling) else ("compute", compute)
        raise ValueError(f"{name}: expected a nik.data.{name.title()}, got {type(got).__name__}")
    sampler, ranges, block_size = sampling.sampler, sampling.ranges, sampling.block_size
    val_fraction, test_fraction = sampling.val_fraction, sampling.test_fraction
    device, chunk_size, compiled, threads = compute.device, compute.chunk_size, compute.compiled, compute.threads
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or int(n) <= 0:
        raise ValueError(f"n must be a positive integer, got {n!r}")
    n = int(n)
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or not 0 <= int(seed) < 2**63:
        raise ValueError(f"seed must be an integer in [0, 2^63), got {seed!r}")
    seed = int(seed)
    if int(chunk_size) <= 0 or int(block_size) <= 0:
        raise ValueError(f"chunk_size and block_size must be positive, got {chunk_size}, {block_size}")
    robot = load_robot(robot)
    dtype_name = dtype if isinstance(dtype, str) else str(dtype).replace("torch.", "")
    if dtype_name not in _DTYPES:
        raise ValueError(f"dtype must be float32 or float64, got {dtype!r}")
    tdtype = _DTYPES[dtype_name]
    from nik.device import resolve_device

    device = resolve_device(device)
    if compiled == "auto":
        compiled = n >= COMPILE_THRESHOLD
    elif not isinstance(compiled, bool):
        raise ValueError(f"compiled must be True, False or 'auto', got {compiled!r}")
    rng, ranges_desc = resolve_ranges(robot, ranges)
    stream = sample_stream(robot.dof, seed, sampler, block_size=int(block_size))
    if sampler == "sobol" and n > _SobolStream.MAX_POINTS:
        raise ValueError(f"the Sobol sampler gives at most 2^30 points, n = {n}")
    splits = _split_sizes(n, val_fraction, test_fraction)
    max_candidates = _SobolStream.MAX_POINTS if sampler == "sobol" else 2**62
    classifier = branch_classifier(robot)
    if branch is not None:
        if isinstance(branch, bool) or not isinstance(branch, (int, np.integer)) or not 0 <= int(branch) <= 7:
            raise ValueError(f"branch must be an integer label 0..7, got {branch!r}")
        branch = int(branch)
        if classifier is None:
            raise ValueError(
                f"--branch: robot {robot.name!r} has no IK branch classification (needs 6 joints, "
                "parallel axes 2 and 3 and a spherical wrist, like puma560 and kuka_kr)"
            )

    rows = (0, n)
    if shard is not None:
        shard = parse_shard(shard)
        if branch is not None:
            raise ValueError(
                "shard: a branch-filtered dataset cannot be sharded (which candidates are kept depends on every "
                "earlier one); generate it in one run"
            )
        rows = shard_rows(n, shard, int(block_size))

    if threads is not None and (isinstance(threads, bool) or not isinstance(threads, int) or threads < 1):
        raise ValueError(f"threads must be a positive integer or None, got {threads!r}")
    previous_threads = torch.get_num_threads()
    if threads is not None:
        torch.set_num_threads(threads)
    try:
        job = _Job(
            robot, n, out, seed, sampler, rng, ranges_desc, splits, tdtype, dtype_name, device, branch, classifier,
            overwrite, int(chunk_size), compiled, progress, fsync, int(block_size), stream, max_candidates, shard, rows,
        )  # fmt: skip
        return _generate(job)
    finally:
        if threads is not None:
            torch.set_num_threads(previous_threads)


@dataclass(frozen=True)
class _Job:
    """One :func:`generate_dataset` run, its arguments checked and resolved: the robot, ``n`` rows and the output
    directory; the randomness (``seed``, ``sampler``, the ranges ``rng (dof, 2)`` and their description, the
    sample ``stream``, ``block_size``, ``max_candidates``); the splits' sizes; the storage dtype (``tdtype``,
    ``dtype_name``); where FK runs (``device``, ``compiled``); the branch filter (``branch``, ``classifier``); how
    it is written (``overwrite``, ``chunk_size``, ``progress``, ``fsync``); and the shard (``shard``, ``rows``:
    ``(start, stop)`` of the rows this run writes; None: all ``n``)."""

    robot: Any
    n: int
    out: Any
    seed: int
    sampler: str
    rng: Any
    ranges_desc: Any
    splits: Any
    tdtype: Any
    dtype_name: str
    device: Any
    branch: Any
    classifier: Any
    overwrite: bool
    chunk_size: int
    compiled: bool
    progress: Any
    fsync: bool
    block_size: int
    stream: Any
    max_candidates: int
    shard: Any = None
    rows: Any = None


def _generate(job: _Job) -> Path:
    """Write the dataset of ``job`` (:class:`_Job`) under a temporary name, then rename it into place."""
    robot, n, out, seed, sampler, rng, ranges_desc, splits = (
        job.robot, job.n, job.out, job.seed, job.sampler, job.rng, job.ranges_desc, job.splits,
    )  # fmt: skip
    tdtype, dtype_name, device, branch, classifier, overwrite = (
        job.tdtype, job.dtype_name, job.device, job.branch, job.classifier, job.overwrite,
    )  # fmt: skip
    chunk_size, compiled, progress, fsync = job.chunk_size, job.compiled, job.progress, job.fsync
    block_size = job.block_size
    stream, max_candidates, shard, rows = job.stream, job.max_candidates, job.shard, job.rows
    row_start, row_stop = rows if rows is not None else (0, n)
    m_rows = row_stop - row_start  # rows this run writes (n unless a shard)
    atomic = AtomicDirectory(out, overwrite=overwrite)
    atomic.prepare()  # validates the destination before any work, creates the temporary directory
    writers: list[NpyStreamWriter] = []
    io = _BackgroundIO()
    bar = None
    try:
        tmp = atomic.tmp
        np_dtype = np.float32 if tdtype == torch.float32 else np.float64
        wq = NpyStreamWriter(tmp / "q.npy", np_dtype, (m_rows, robot.dof))
        wp = NpyStreamWriter(tmp / "pose.npy", np_dtype, (m_rows, 4, 4))
        writers += [wq, wp]
        wb = None
        if classifier is not None:
            wb = NpyStreamWriter(tmp / "branch.npy", np.uint8, (m_rows,))
            writers.append(wb)

        desc = f"nik generate {robot.name}" + ("" if shard is None else f" shard {shard[0]}/{shard[1]}")
        bar = _progress(m_rows, progress, desc)
        chunk, fk_block = int(chunk_size), int(block_size)
        cand = row_start  # candidates drawn (a shard starts at its first row: no filter, one candidate per row)
        drawn = row_start  # samples accepted so far (== row_stop when done)
        pending: list[tuple[torch.Tensor, torch.Tensor | None]] = []  # accepted, not yet written
        n_pending = 0
        counts = np.zeros(8, dtype=np.int64)

        def write_block(m: int) -> None:
            # FK and writing always cover the output rows [k * fk_block, (k + 1) * fk_block) (the last one
            # shorter), whatever the chunk size, so a compiled FK sees the same batches too
            nonlocal pending, n_pending
            qs = torch.cat([p[0] for p in pending]) if len(pending) > 1 else pending[0][0]
            labs = None
            if wb is not None:
                labs = torch.cat([p[1] for p in pending]) if len(pending) > 1 else pending[0][1]
            q_out, rest_q = qs[:m], qs[m:]
            pending = [(rest_q, None if labs is None else labs[m:])] if rest_q.shape[0] else []
            n_pending -= m
            qd = q_out.to(device=device, dtype=torch.float64)  # exactly the stored joints
            pose = robot.fk(qd, compiled=compiled).to(device="cpu", dtype=tdtype)
            io.submit(wq.write, q_out.numpy())
            io.submit(wp.write, pose.numpy())
            if wb is not None:
                lab = labs[:m].numpy()
                io.submit(wb.write, lab)
                counts[:] += np.bincount(lab, minlength=8)
            if bar is not None:
                bar.update(m)

        while drawn < row_stop:
            m = min(chunk, row_stop - drawn) if branch is None else chunk  # rejection: fixed candidate chunks
            if cand + m > max_candidates:
                raise DatasetError(
                    f"branch {branch} ({branch_name(branch)}): only {drawn} of {n} samples found in {cand} candidates"
                )
            q = _to_joints(stream.draw(cand, cand + m), rng, tdtype)
            cand += m
            labels = classifier(q) if classifier is not None else None
            if branch is not None:
                sel = (labels == branch).nonzero().squeeze(-1)[: n - drawn]
                q, labels = q[sel], labels[sel]
                if drawn == 0 and q.shape[0] == 0 and cand >= 64 * fk_block:
                    raise DatasetError(
                        f"branch {branch} ({branch_name(branch)}) did not occur in {cand} samples "
                        f"within the ranges of robot {robot.name!r}; it is (nearly) unreachable there"
                    )
            if q.shape[0]:
                pending.append((q, labels))
                n_pending += q.shape[0]
                drawn += q.shape[0]
            while n_pending >= fk_block or (drawn == row_stop and n_pending > 0):
                write_block(min(fk_block, n_pending))
            q = labels = None  # free the chunk before drawing the next

        files = {}
        io.drain()
        for w in writers:
            digest = w.close(fsync=fsync)
            files[w.path.name] = {
                "sha256": digest,
                "bytes": w.path.stat().st_size,
                "shape": list(w.shape),
                "dtype": str(w.dtype),
            }
        meta = {
            "format": {"name": "nik-dataset", "version": FORMAT_VERSION},
            "n": n,
            "dof": robot.dof,
            "dtype": dtype_name,
            "robot": {
                "name": robot.name,
                "definition_hash": robot.definition_hash,
                "source": getattr(robot, "source", None),
                "definition": robot.to_definition(),
                **_flange_meta(robot),
            },
            "sampler": sampler,
            "ranges": {"source": ranges_desc, "radians": rng.tolist()},
            "seed": seed,
            "block_size": int(block_size),
            "splits": splits,
            "split_sizes": {k: b - a for k, (a, b) in splits.items()},
            "branch": None
            if classifier is None
            else {
                "filter": branch,
                "candidates": cand - row_start,
                "counts": counts.tolist(),
                "names": [branch_name(k) for k in range(8)],
                "definition": "nik.data.branches (shoulder front/back, elbow up/down, wrist noflip/flip)",
            },
            "fk": {"dtype": "float64", "device": str(device), "compiled": bool(compiled)},
            "units": {"q": "rad", "pose": "m"},
            "nik_version": nik.__version__,
            "torch_version": torch.__version__,
            "created": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
            "files": files,
        }
        if shard is not None:
            # a part, not a dataset: load_dataset refuses it, nik data merge joins the parts
            meta["shard"] = {"index": shard[0], "count": shard[1], "rows": [row_start, row_stop]}
        write_meta(tmp, meta)
        if bar is not None:
            bar.close()
            bar = None
        return atomic.commit()
    except BaseException:
        io.cancel()
        for w in writers:
            w.abort()
        if bar is not None:
            bar.close()
        atomic.abort()
        raise
