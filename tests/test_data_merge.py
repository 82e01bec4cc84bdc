"""Sharded generation (``generate_dataset(shard=...)``, ``nik generate --shard I/N``) and
``merge_shards`` / ``nik data merge``: the merged dataset is the single-process one, file for file."""

import json

import numpy as np
import pytest

import nik
from nik.cli import main
from nik.data import Compute, Sampling, generate_dataset, load_dataset, merge_shards, shard_rows
from nik.errors import DatasetError

BLOCK = 1000  # small randomness blocks: several shards of a small dataset (the CLI keeps the default)


def _gen(robot, out, shard=None, **kw):
    args = dict(seed=5, block_size=BLOCK, chunk_size=700, progress=False, fsync=False)
    args.update(kw)
    sampling = Sampling(**{k: args.pop(k) for k in ("sampler", "block_size") if k in args})
    return generate_dataset(
        robot, 3500, out, shard=shard, sampling=sampling, compute=Compute(chunk_size=args.pop("chunk_size")), **args
    )


def _assert_same_dataset(a, b):
    """Every array file byte for byte, and the metadata except its creation time."""
    for f in ("q.npy", "pose.npy", "branch.npy", "meta.json"):
        assert (a / f).exists() == (b / f).exists(), f
    for f in ("q.npy", "pose.npy", "branch.npy"):
        if (a / f).exists():
            assert (a / f).read_bytes() == (b / f).read_bytes(), f
    ma, mb = json.loads((a / "meta.json").read_text()), json.loads((b / "meta.json").read_text())
    ma.pop("created"), mb.pop("created")
    assert ma == mb
    da, db = load_dataset(a), load_dataset(b)
    for name in ("train", "val", "test"):
        assert np.array_equal(np.asarray(da.split(name).q), np.asarray(db.split(name).q))
        assert np.array_equal(np.asarray(da.split(name).pose), np.asarray(db.split(name).pose))


@pytest.mark.parametrize("sampler, dtype", [("uniform", "float64"), ("sobol", "float32")])
def test_merged_shards_equal_the_single_process_dataset(tmp_path, sampler, dtype):
    kuka = nik.load_robot("kuka_kr")  # has branch labels: their counts are summed over shards
    whole = _gen(kuka, tmp_path / "whole", sampler=sampler, dtype=dtype)
    shards = [_gen(kuka, tmp_path / f"s{i}", shard=(i, 3), sampler=sampler, dtype=dtype) for i in range(3)]
    merged = merge_shards(tmp_path / "merged", [shards[2], shards[0], shards[1]], fsync=False)  # any order
    _assert_same_dataset(whole, merged)
    assert sum(load_dataset(merged).meta["branch"]["counts"]) == 3500


def test_shards_are_whole_blocks_spread_evenly():
    assert [shard_rows(3500, (i, 3), 1000) for i in range(3)] == [(0, 1000), (1000, 2000), (2000, 3500)]
    assert [shard_rows(4000, (i, 2), 1000) for i in range(2)] == [(0, 2000), (2000, 4000)]
    # more shards than blocks: some are empty, and the shards still tile the rows
    assert [shard_rows(2500, (i, 5), 1000) for i in range(5)] == [
        (0, 0),
        (0, 1000),
        (1000, 1000),
        (1000, 2000),
        (2000, 2500),
    ]
    for bad in ("3/3", "-1/2", "1", "a/b", (2, 1)):
        with pytest.raises(ValueError, match="I/N"):
            shard_rows(3500, bad, 1000)


@pytest.fixture(scope="module")
def three(tmp_path_factory):
    root = tmp_path_factory.mktemp("shards")
    kuka = nik.load_robot("kuka_kr")
    return [_gen(kuka, root / f"s{i}", shard=(i, 3)) for i in range(3)]


def test_more_shards_than_blocks_gives_empty_shards_that_merge_too(tmp_path):
    kuka = nik.load_robot("kuka_kr")
    whole = _gen(kuka, tmp_path / "whole", block_size=4096)  # 3500 samples: one block
    shards = [_gen(kuka, tmp_path / f"s{i}", shard=(i, 3), block_size=4096) for i in range(3)]
    assert [len(np.load(s / "q.npy")) for s in shards] == [0, 0, 3500]
    _assert_same_dataset(whole, merge_shards(tmp_path / "merged", shards, fsync=False))


def test_a_shard_is_not_loadable_as_a_dataset(three):
    with pytest.raises(DatasetError, match="shard 0/3 .* nik data merge"):
        load_dataset(three[0])


def test_merge_refuses_missing_duplicate_and_foreign_shards(three, tmp_path):
    with pytest.raises(DatasetError, match="2/3 missing"):
        merge_shards(tmp_path / "m", three[:2])
    with pytest.raises(DatasetError, match="shard 1/3 given twice"):
        merge_shards(tmp_path / "m", [three[0], three[1], three[1], three[2]])
    other = _gen("kuka_kr", tmp_path / "other_seed", shard=(2, 3), seed=6)
    with pytest.raises(DatasetError, match="different datasets .*seed"):
        merge_shards(tmp_path / "m", [three[0], three[1], other])
    half = _gen("kuka_kr", tmp_path / "half", shard=(1, 2))
    with pytest.raises(DatasetError, match="shard of 2"):
        merge_shards(tmp_path / "m", [three[0], three[1], half])
    whole = _gen("kuka_kr", tmp_path / "whole")
    with pytest.raises(DatasetError, match="whole dataset, not a shard"):
        merge_shards(tmp_path / "m", [whole, *three])
    assert not (tmp_path / "m").exists()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".m.")]  # no temporary left behind


def test_merge_refuses_a_corrupt_shard_and_leaves_nothing(three, tmp_path):
    bad = tmp_path / "bad"
    bad.mkdir()
    for f in three[1].iterdir():
        (bad / f.name).write_bytes(f.read_bytes())
    data = bytearray((bad / "q.npy").read_bytes())
    data[-1] ^= 0xFF
    (bad / "q.npy").write_bytes(bytes(data))
    with pytest.raises(DatasetError, match="q.npy: SHA-256 checksum mismatch"):
        merge_shards(tmp_path / "m", [three[0], bad, three[2]])
    assert not (tmp_path / "m").exists()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".m.")]


def test_branch_filtered_datasets_cannot_be_sharded(tmp_path):
    with pytest.raises(ValueError, match="branch-filtered dataset cannot be sharded"):
        _gen("kuka_kr", tmp_path / "b", shard=(0, 2), branch=0)


def test_cli_generate_shard_and_data_merge(tmp_path, capsys):
    # the CLI's randomness blocks are 65,536 samples: 2 shards need more than one block
    common = ["--robot", "puma560", "--n", "70000", "--seed", "2", "--no-progress"]
    assert main(["generate", *common, "--out", str(tmp_path / "whole")]) == 0
    for i in range(2):
        assert main(["generate", *common, "--out", str(tmp_path / f"s{i}"), "--shard", f"{i}/2"]) == 0
    out = capsys.readouterr().out
    assert "shard 1/2 (rows 65536..69999 of 70000)" in out
    assert main(["data", "merge", str(tmp_path / "merged"), str(tmp_path / "s1"), str(tmp_path / "s0")]) == 0
    assert "merged 2 shards" in capsys.readouterr().out
    _assert_same_dataset(tmp_path / "whole", tmp_path / "merged")
    # one-line errors, exit code 2
    assert main(["data", "merge", str(tmp_path / "m2"), str(tmp_path / "s0")]) == 2
    assert "shard(s) 1/2 missing" in capsys.readouterr().err
    assert main(["generate", *common, "--out", str(tmp_path / "x"), "--shard", "2/2"]) == 2
    assert "0 <= I < N" in capsys.readouterr().err


def test_merge_refuses_an_output_that_is_one_of_its_inputs(tmp_path, capsys):
    shards = [_gen("kuka_kr", tmp_path / f"s{i}", shard=(i, 2)) for i in range(2)]
    before = {f.name: f.read_bytes() for f in shards[1].iterdir()}
    with pytest.raises(DatasetError, match=f"the output {shards[1]} is one of the inputs"):
        merge_shards(shards[1], shards, overwrite=True)
    assert {f.name: f.read_bytes() for f in shards[1].iterdir()} == before  # the shard is untouched
    # a shard inside the output folder would go with it too
    inner = _gen("kuka_kr", tmp_path / "out" / "s0", shard=(0, 2))
    with pytest.raises(DatasetError, match="holds input"):
        merge_shards(tmp_path / "out", [inner, shards[1]], overwrite=True)
    assert main(["data", "merge", str(shards[0]), *map(str, shards), "--overwrite"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"output {shards[0]} is one of the inputs" in err
    assert len(merge_shards(tmp_path / "merged", shards, fsync=False).name) > 0  # elsewhere it merges
