"""Hostile archives: zip and tensor bombs, lying directories, huge declared arrays.

Every case is refused with one line, fast, whatever sizes the file declares
(:class:`aftir_rl.core.archives.BoundedZip`, the SB3 and tabular loaders); the two reproductions
of the issue are also measured in a subprocess (peak memory).
"""

from __future__ import annotations

import collections
import dataclasses
import io
import os
import pickle
import struct
import subprocess
import sys
import time
import zipfile
import zlib
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

from aftir_rl.core.archives import MAX_DIRECTORY_BYTES, BoundedZip
from aftir_rl.core.errors import CheckpointError
from aftir_rl.rl.sb3 import load_model
from aftir_rl.rl.tabular.checkpoint import read_q_table
from aftir_rl.rl.tabular.q_table import QLearning

MIB = 1 << 20
STORED, DEFLATED = zipfile.ZIP_STORED, zipfile.ZIP_DEFLATED

#: The peak memory [bytes] a subprocess loading a hostile file may reach (torch, SB3 and the
#: model it builds take about 380 MB).
PEAK_LIMIT = 600 * MIB


def _raw_zip(entries) -> bytes:
    """A zip of ``(name, method, crc, declared_size, payload)``, the sizes as declared."""
    out, directory = bytearray(), bytearray()
    for name, method, crc, size, payload in entries:
        n, at = name.encode(), len(out)
        fields = (20, 0, method, 0, 0x21, crc, len(payload), size, len(n), 0)
        out += struct.pack("<4s5H3L2H", b"PK\x03\x04", *fields) + n + payload
        fields = (20, 20, 0, method, 0, 0x21, crc, len(payload), size, len(n), 0, 0, 0, 0, 0, at)
        directory += struct.pack("<4s6H3L5H2L", b"PK\x01\x02", *fields) + n
    count = min(len(entries), 0xFFFF)
    end = (0, 0, count, count, len(directory), len(out), 0)
    return bytes(out + directory + struct.pack("<4s4H2LH", b"PK\x05\x06", *end))


def _deflate(data: bytes) -> bytes:
    c = zlib.compressobj(9, zlib.DEFLATED, -15)
    return c.compress(data) + c.flush()


def _zeros_deflated(mib: int) -> bytes:
    """A raw deflate stream of ``mib`` MiB of zeros, ~1 kB a MiB, built without inflating it."""
    c = zlib.compressobj(9, zlib.DEFLATED, -15)
    block = c.compress(bytes(MIB)) + c.flush(zlib.Z_FULL_FLUSH)  # the same after each flush
    return block * mib + zlib.compressobj(9, zlib.DEFLATED, -15).flush()


def _entry(name: str, data: bytes, method: int = STORED):
    payload = _deflate(data) if method == DEFLATED else data
    return (name, method, zlib.crc32(data), len(data), payload)


def _torch_records() -> dict[str, bytes]:
    import torch

    buffer = io.BytesIO()
    torch.save({"w": torch.zeros(4)}, buffer)
    with zipfile.ZipFile(buffer) as z:
        return {n: z.read(n) for n in z.namelist()}


def _data_pkl(numel: int) -> bytes:
    """torch's ``data.pkl`` of ``{"w": <float tensor of numel>}`` in record ``data/0``."""
    import torch

    storage = object()

    class Tensor:
        def __reduce__(self):
            args = (storage, 0, (numel,), (1,), False, collections.OrderedDict())
            return (torch._utils._rebuild_tensor_v2, args)

    class Pickler(pickle.Pickler):
        def persistent_id(self, obj):
            if obj is storage:
                return ("storage", torch.FloatStorage, "0", "cpu", numel)
            return None

    buffer = io.BytesIO()
    Pickler(buffer, protocol=2).dump({"w": Tensor()})
    return buffer.getvalue()


def _pth(numel: int | None = None, bomb: tuple[int, int] | None = None) -> bytes:
    """A torch file: ``numel`` declared in data.pkl; ``bomb``: record data/0 as
    ``(MiB of zeros deflated, declared size)``."""
    records = _torch_records()
    prefix = next(n for n in records if n.endswith("data.pkl"))[: -len("data.pkl")]
    if numel is not None:
        records[prefix + "data.pkl"] = _data_pkl(numel)
    entries = [_entry(n, d) for n, d in records.items()]
    if bomb:
        i = [e[0] for e in entries].index(prefix + "data/0")
        entries[i] = (prefix + "data/0", DEFLATED, 0, bomb[1], _zeros_deflated(bomb[0]))
    return _raw_zip(entries)


@pytest.fixture(scope="module")
def model_zip(tmp_path_factory) -> Path:
    """A clean PPO model of AFTIR-ArmReach-v0, as SB3 saves it."""
    from stable_baselines3 import PPO

    path = tmp_path_factory.mktemp("model") / "model.zip"
    PPO("MlpPolicy", gym.make("AFTIR-ArmReach-v0"), n_steps=64, batch_size=32, seed=0).save(path)
    return path


def _model_with(model_zip: Path, dest: Path, replace: dict, method: int = STORED) -> Path:
    """``model_zip`` with entries replaced (bytes, or a raw entry tuple) or added."""
    with zipfile.ZipFile(model_zip) as z:
        files: dict = {n: z.read(n) for n in z.namelist()}
    files.update(replace)
    entries = [d if isinstance(d, tuple) else _entry(n, d, method) for n, d in files.items()]
    dest.write_bytes(_raw_zip(entries))
    return dest


def _refused(load, *args, match: str = "", seconds: float = 1.0) -> str:
    start = time.perf_counter()
    with pytest.raises(CheckpointError, match=match) as info:
        load(*args)
    assert time.perf_counter() - start < seconds
    message = str(info.value)
    assert "\n" not in message and len(message) < 600
    return message


# ---------------------------------------------------------------- BoundedZip


def test_bounded_zip_reads_counts_and_repacks():
    raw = _raw_zip([_entry("a", b"x" * 1000, DEFLATED), _entry("b", b"y" * 10)])
    with BoundedZip(raw, "t.zip", budget=2100, max_entries=2) as zf:
        assert zf.names == ["a", "b"] and zf.read("a") == b"x" * 1000 and zf.left == 1100
        _refused(zf.read, "b", 5, match="'b' is larger than 5 bytes")
        _refused(zf.read, "c", match="no 'c' entry")
        packed = zipfile.ZipFile(zf.repack())
    assert [(i.filename, i.compress_type) for i in packed.infolist()] == [("a", 0), ("b", 0)]
    assert packed.read("a") == b"x" * 1000
    with BoundedZip(raw, "t.zip", budget=1005, max_entries=2) as zf:
        _refused(zf.repack, match="'b' takes the entries past 1,005 bytes in all")


def test_understated_entry_is_never_inflated_past_its_declared_size():
    raw = _raw_zip([("bomb", DEFLATED, 0, 1000, _zeros_deflated(2048))])  # 2 GB declared 1 kB
    with BoundedZip(raw, "t.zip", budget=64 * MIB, max_entries=1) as zf:
        _refused(zf.read, "bomb", match="not a readable zip archive.*CRC")


def test_declared_sizes_refused_before_inflating_and_every_read_counted():
    bomb = ("bomb", DEFLATED, 0, 2048 * MIB, _zeros_deflated(2048))
    with BoundedZip(_raw_zip([bomb]), "t.zip", budget=64 * MIB, max_entries=1) as zf:
        _refused(zf.read, "bomb", match="past 67,108,864 bytes in all")
    entry = ("a", DEFLATED, zlib.crc32(bytes(40 * MIB)), 40 * MIB, _zeros_deflated(40))
    with BoundedZip(_raw_zip([entry]), "t.zip", budget=64 * MIB, max_entries=1) as zf:
        assert len(zf.read("a")) == 40 * MIB and zf.left == 24 * MIB
        _refused(zf.read, "a", match="past")


@pytest.mark.parametrize(
    "entries, message",
    [
        ([_entry("a", b"")] * 3, "3 entries, more than 2"),
        ([_entry("a", b""), _entry("a", b"")], "an entry twice"),
        ([("a", zipfile.ZIP_BZIP2, 0, 1, b"x")], "compression method 12"),
    ],
)
def test_archives_refused_as_a_whole(entries, message):
    _refused(BoundedZip, _raw_zip(entries), "t.zip", 64 * MIB, 2, match=message)


def test_a_long_directory_is_refused_before_parsing():
    count = MAX_DIRECTORY_BYTES // 50 + 1000
    head = _raw_zip([_entry("0", b"")])
    local = head[: head.index(b"PK\x01\x02")]
    directory = b"".join(
        struct.pack(
            "<4s6H3L5H2L", b"PK\x01\x02", 20, 20, 0, 0, 0, 0x21, 0, 0, 0, 5, 0, 0, 0, 0, 0, 0
        )
        + f"{i:05x}".encode()
        for i in range(count)
    )
    end = struct.pack(
        "<4s4H2LH", b"PK\x05\x06", 0, 0, 0xFFFF, 0xFFFF, len(directory), len(local), 0
    )
    _refused(BoundedZip, local + directory + end, "t.zip", 64 * MIB, 10**6, match="directory")


def test_encrypted_entry_refused():
    raw = bytearray(_raw_zip([_entry("a", b"x")]))
    for sig, at in ((b"PK\x03\x04", 6), (b"PK\x01\x02", 8)):  # the flag bits
        i = raw.index(sig) + at
        raw[i] |= 1
    _refused(BoundedZip, bytes(raw), "t.zip", 64, 1, match="encrypted")


# ---------------------------------------------------------------- SB3 models


def test_deflated_model_with_compressed_records_loads(model_zip, tmp_path):
    import torch

    with zipfile.ZipFile(model_zip) as z:
        files = {n: z.read(n) for n in z.namelist()}
    for name in [n for n in files if n.endswith(".pth")]:  # torch records compressed too
        with zipfile.ZipFile(io.BytesIO(files[name])) as src:
            records = [_entry(n, src.read(n), DEFLATED) for n in src.namelist()]
        files[name] = _raw_zip(records)
    path = tmp_path / "deflated.zip"
    path.write_bytes(_raw_zip([_entry(n, d, DEFLATED) for n, d in files.items()]))
    model, clean = load_model("ppo", path), load_model("ppo", model_zip)
    for a, b in zip(model.policy.parameters(), clean.policy.parameters(), strict=True):
        assert torch.equal(a, b)


def _understated(model_zip: Path, dest: Path) -> Path:
    """The issue's first reproduction: policy.pth inflates to 2 GB but declares 1 kB."""
    return _model_with(
        model_zip, dest, {"policy.pth": ("policy.pth", DEFLATED, 0, 1000, _zeros_deflated(2048))}
    )


def _pth_bomb(model_zip: Path, dest: Path) -> Path:
    """The second: a 1.5 GB deflated record inside policy.pth, the model file ~10 kB."""
    pth = _pth(numel=1536 * MIB // 4, bomb=(1536, 1536 * MIB))
    return _model_with(model_zip, dest, {"policy.pth": pth}, DEFLATED)


@pytest.mark.parametrize(
    "make, message",
    [
        (_understated, "not a readable SB3 model.*CRC"),
        (_pth_bomb, "policy.pth: '.*data/0' takes the entries past 64,000,000 bytes"),
        (
            lambda m, d: _model_with(m, d, {"policy.pth": _pth(bomb=(1536, 1000))}, DEFLATED),
            "not a readable tensor file.*CRC",
        ),
        (
            lambda m, d: _model_with(m, d, {"policy.pth": _pth(numel=10**9)}),
            "policy.pth holds more than tensors .*record size",
        ),
        (lambda m, d: _model_with(m, d, {"data": b" " * 1_000_001}), "'data' is larger than"),
        (lambda m, d: _model_with(m, d, {"notes.txt": b"hi"}), "'notes.txt', which SB3 does not"),
        (
            lambda m, d: _model_with(m, d, {f"x{i}": b"" for i in range(20)}),
            "entries, more than 16",
        ),
    ],
    ids=["understated", "pth_bomb", "pth_understated", "numel", "data", "extra", "many"],
)
def test_hostile_models_refused_fast(model_zip, tmp_path, make, message):
    path = make(model_zip, tmp_path / "model.zip")
    env = gym.make("AFTIR-ArmReach-v0")
    _refused(load_model, "ppo", path, env, match=message)


_PEAK = """
import sys
from aftir_rl.core.errors import CheckpointError
from aftir_rl.rl.sb3 import load_model
from aftir_rl.rl.tabular.checkpoint import read_q_table
kind, path = sys.argv[1:]
try:
    load_model("ppo", path) if kind == "sb3" else read_q_table(path)
except CheckpointError as exc:
    print(exc)
# VmHWM: this program's own peak (ru_maxrss keeps the forking pytest worker's too)
hwm = [l for l in open("/proc/self/status") if l.startswith("VmHWM:")][0].split()[1]
print(int(hwm) * 1024)
"""


def _peak(kind: str, path: Path) -> tuple[str, int]:
    out = subprocess.run(
        [sys.executable, "-c", _PEAK, kind, str(path)], capture_output=True, text=True
    )
    assert out.returncode == 0, out.stderr
    message, peak = out.stdout.strip().splitlines()
    return message, int(peak)


@pytest.mark.slow
@pytest.mark.parametrize("make", [_understated, _pth_bomb], ids=["understated", "pth_bomb"])
def test_reproductions_stay_under_the_memory_limit(model_zip, tmp_path, make):
    message, peak = _peak("sb3", make(model_zip, tmp_path / "model.zip"))
    assert "refused" in message or "not a readable" in message
    assert peak < PEAK_LIMIT, f"{peak / MIB:.0f} MiB"


# ---------------------------------------------------------------- tabular checkpoints


def _npy(array: np.ndarray) -> bytes:
    buffer = io.BytesIO()
    np.save(buffer, array, allow_pickle=True)
    return buffer.getvalue()


def _npy_header(descr: str, shape: tuple) -> bytes:
    buffer = io.BytesIO()
    header = {"descr": descr, "fortran_order": False, "shape": shape}
    np.lib.format.write_array_header_1_0(buffer, header)
    return buffer.getvalue()


@pytest.fixture(scope="module")
def q_entries(tmp_path_factory) -> dict[str, bytes]:
    path = QLearning(gym.make("AFTIR-Tank-v0")).save(tmp_path_factory.mktemp("q") / "q.npz")
    with zipfile.ZipFile(path) as z:
        return {n: z.read(n) for n in z.namelist()}


class _Payload:
    def __reduce__(self):
        return (exec, ("raise SystemExit('unpickled')",))


@pytest.mark.parametrize(
    "replace, message",
    [
        ({}, None),
        (  # the metadata's JSON bomb (240 MB of "[[],[],...") declared as it is
            {"metadata.npy": ("metadata.npy", DEFLATED, 0, 240 * MIB, _zeros_deflated(240))},
            "'metadata.npy' is larger than 1,000,000 bytes",
        ),
        (  # 2 GB of table declared 1 kB
            {"q_table.npy": ("q_table.npy", DEFLATED, 0, 1000, _zeros_deflated(2048))},
            "not a readable Q-table checkpoint.*CRC",
        ),
        (
            {"q_table.npy": ("q_table.npy", DEFLATED, 0, 300 * MIB, _zeros_deflated(300))},
            "past 256,000,000 bytes",
        ),
        ({"q_table.npy": _npy_header("<f8", (10**12, 6)) + bytes(48)}, "over 48 bytes of data"),
        ({"q_table.npy": _npy(np.array([_Payload()]))}, "Python objects"),
        ({"metadata.npy": _npy(np.array("[" * 100_000))}, "not a readable Q-table checkpoint"),
        ({"metadata.npy": _npy(np.array(["{}", "{}"]))}, "not a readable Q-table checkpoint"),
    ],
    ids=["clean", "json_bomb", "understated", "declared", "shape", "objects", "deep", "meta"],
)
def test_hostile_q_tables_refused_fast(q_entries, tmp_path, replace, message):
    files = {**q_entries, **replace}
    path = tmp_path / "q.npz"
    path.write_bytes(
        _raw_zip([d if isinstance(d, tuple) else _entry(n, d) for n, d in files.items()])
    )
    if message is None:
        q_table, meta = read_q_table(path)
        assert q_table.shape == (750, 6) and q_table.flags.writeable and meta["episodes_done"] == 0
    else:
        _refused(read_q_table, path, match=message)


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs here")
def test_fifo_checkpoints_refused_without_blocking(tmp_path):
    fifo = tmp_path / "q.npz"
    os.mkfifo(fifo)
    _refused(read_q_table, fifo, match="cannot read")
    model = tmp_path / "model.zip"
    os.mkfifo(model)
    _refused(load_model, "ppo", model, gym.make("AFTIR-ArmReach-v0"), match="no such model")


@pytest.mark.slow
@pytest.mark.parametrize("algo", ["ppo", "sac"])
def test_the_largest_network_the_trainer_allows_loads_again(tmp_path, algo):
    """One size limit: the widest net_arch that training accepts round-trips through the loader,
    and one layer width more is refused before training."""
    from aftir_rl.core.errors import ConfigError
    from aftir_rl.rl.sb3 import build_model, entry_config, save_model
    from aftir_rl.rl.sb3.config import MAX_MODEL_BYTES, model_bytes
    from aftir_rl.rl.sb3.vec_adapter import make_sb3_vec_env

    env_id = "AFTIR-ArmReach-v0"
    venv = make_sb3_vec_env(env_id, 1)
    base = entry_config(algo, env_id)

    def config(width):
        hyper = {**base.hyperparameters, "policy_kwargs": {"net_arch": [width] * 3}}
        if algo == "sac":
            hyper.update(buffer_size=100, learning_starts=10, batch_size=8)
        else:
            hyper.update(n_steps=16, batch_size=16)
        return dataclasses.replace(base, hyperparameters=hyper)

    def size(width):
        try:
            return model_bytes(build_model(algo, config(width), venv))
        except ConfigError:
            return MAX_MODEL_BYTES + 1

    lo, hi = 16, 4096  # the widest width whose model the trainer builds
    while hi - lo > 1:
        mid = (lo + hi) // 2
        lo, hi = (mid, hi) if size(mid) <= MAX_MODEL_BYTES else (lo, mid)
    model = build_model(algo, config(lo), venv)
    model.learn(32)  # the optimizers hold their moments, as a trained run's do
    save_model(model, tmp_path / "model.zip")
    loaded = load_model(algo, tmp_path / "model.zip", env=venv, config=config(lo))
    assert model_bytes(loaded) == model_bytes(model) <= MAX_MODEL_BYTES
    with pytest.raises(ConfigError, match="use narrower layers"):
        build_model(algo, config(lo + 1), venv)
