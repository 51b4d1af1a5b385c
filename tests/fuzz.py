"""A run-directory fuzzer: random mutations of real run directories, fed to a command line.

``python -m tests.fuzz CLI SEED CASES WORKDIR RUN_DIR...`` copies a random ``RUN_DIR`` for every
case, applies one to three random mutations (JSON fields and keys, file types, sizes, symlinks,
bytes, zip and npz members), runs the command line ``CLI`` (view, evaluate, rollout, rank,
check, export, tank show, or the ``--demos`` reader of ``aftir train``) in this process on it
with a time limit, and prints one JSON object: every case's exit status,
stderr, seconds, mutations, the memory allocated before it and at its peak (:func:`allocated_mb`)
and its peak resident size (``tests/cli/test_fuzz_runs.py`` asserts on them).
"""

from __future__ import annotations

import contextlib
import ctypes
import gc
import importlib.util
import io
import json
import os
import random
import resource
import shutil
import signal
import sys
import time
import traceback
import warnings
import zipfile
import zlib
from collections.abc import Callable
from pathlib import Path
from typing import Any

#: The longest a case may run [s] before it counts as a hang.
CASE_SECONDS = 10

HOSTILE_VALUES: list[Any] = [
    None,
    True,
    -1,
    0,
    2**63,
    10**30,
    1e308,
    -1e308,
    float("nan"),
    float("inf"),
    "NaN",
    "",
    "x" * 10_000,
    "\x00\x1b[2J",
    "/etc/passwd",
    "/etc/shadow",
    "/dev/zero",
    "/proc/self/mem",
    "../../../../etc/passwd",
    "../tank.yaml",
    "tank.yaml",
    "b737_center",
    "AFTIR-ArmFTL-v0",
    "os:system",
    [],
    {},
    [[1, 2]],
    [1e308, 1e308, 1e308],
    [0.0] * 300_000,
    {"a": {"b": {"c": [1]}}},
]


class Hang(BaseException):
    """A case ran past :data:`CASE_SECONDS` (BaseException: no ``except Exception`` eats it)."""


def _files(run: Path) -> list[Path]:
    """The regular files of ``run`` small enough to rewrite (earlier mutations may leave others)."""
    found = [p for p in run.rglob("*") if p.is_file() and not p.is_symlink()]
    return sorted(p for p in found if p.stat().st_size < 50_000_000) or [run / "missing.json"]


def _deep(depth: int) -> str:
    return "[" * depth + "]" * depth


def _mutate_value(rng: random.Random, data: Any) -> Any:
    """``data`` with one random node replaced, removed, or given an unknown key."""
    if isinstance(data, dict) and data:
        key = rng.choice(sorted(data, key=str))
        roll = rng.random()
        if roll < 0.15:
            del data[key]
        elif roll < 0.25:
            data[rng.choice(["evil", "__class__", "tank", "env_id", "algo"])] = rng.choice(
                HOSTILE_VALUES
            )
        elif roll < 0.6 and isinstance(data[key], (dict, list)):
            data[key] = _mutate_value(rng, data[key])
        else:
            data[key] = rng.choice(HOSTILE_VALUES)
        return data
    if isinstance(data, list) and data:
        i = rng.randrange(len(data))
        if rng.random() < 0.5 and isinstance(data[i], (dict, list)):
            data[i] = _mutate_value(rng, data[i])
        elif rng.random() < 0.5:
            data[i] = rng.choice(HOSTILE_VALUES)
        else:
            del data[i:]
        return data
    return rng.choice(HOSTILE_VALUES)


def mutate_json(rng: random.Random, run: Path) -> str:
    files = [p for p in _files(run) if p.suffix == ".json"]
    if not files:
        return "json: none"
    path = rng.choice(files)
    try:
        data = json.loads(path.read_text())
    except (ValueError, UnicodeDecodeError, RecursionError):
        return "json: unreadable"
    if rng.random() < 0.1:
        path.write_text(_deep(rng.choice([100, 5000, 200_000])))
        return f"json deep {path.name}"
    if rng.random() < 0.2 and isinstance(data, dict):
        data["tank"] = rng.choice(HOSTILE_VALUES[10:22])
        if isinstance(data.get("env_kwargs"), dict):
            data["env_kwargs"]["tank"] = data["tank"]
    else:
        data = _mutate_value(rng, data)
    path.write_text(json.dumps(data))
    return f"json {path.name}"


def mutate_type(rng: random.Random, run: Path) -> str:
    files = _files(run)
    path = rng.choice(files)
    path.unlink()
    kind = rng.choice(["fifo", "dir", "zero", "passwd", "loop", "dangling", "empty", "self"])
    if kind == "fifo":
        os.mkfifo(path)
    elif kind == "dir":
        path.mkdir()
    elif kind == "zero":
        path.symlink_to("/dev/zero")
    elif kind == "passwd":
        path.symlink_to("/etc/passwd")
    elif kind == "loop":
        path.symlink_to(path.name)
    elif kind == "dangling":
        path.symlink_to(path.parent / "missing")
    elif kind == "self":
        path.symlink_to(run.parent)
    else:
        path.write_bytes(b"")
    return f"type {path.name}: {kind}"


def mutate_size(rng: random.Random, run: Path) -> str:
    path = rng.choice(_files(run))
    size = path.stat().st_size
    roll = rng.random()
    with open(path, "r+b") as fh:
        if roll < 0.4:
            fh.truncate(rng.randrange(size + 1))
            return f"truncate {path.name}"
        if roll < 0.7:
            fh.seek(0, 2)
            fh.write(rng.randbytes(rng.randrange(1, 4096)))
            return f"append {path.name}"
        fh.truncate(rng.choice([20_000_000, 600_000_000, 5_000_000_000]))  # sparse
    return f"sparse {path.name}"


def mutate_bytes(rng: random.Random, run: Path) -> str:
    path = rng.choice(_files(run))
    raw = bytearray(path.read_bytes())
    for _ in range(rng.randrange(1, 9)):
        if raw:
            raw[rng.randrange(len(raw))] = rng.randrange(256)
    path.write_bytes(bytes(raw))
    return f"bytes {path.name}"


_BOMB: dict[int, tuple[bytes, int]] = {}


def _bomb(size: int) -> tuple[bytes, int]:
    """``size`` zero bytes raw-deflated (a few MB for 2 GB) and their CRC, made once."""
    if size not in _BOMB:
        comp = zlib.compressobj(9, zlib.DEFLATED, -15)
        chunk, crc, parts = bytes(1 << 20), 0, []
        for _ in range(size >> 20):
            parts.append(comp.compress(chunk))
            crc = zlib.crc32(chunk, crc)
        _BOMB[size] = (b"".join(parts) + comp.flush(), crc)
    return _BOMB[size]


def _add_bomb(z: zipfile.ZipFile, name: str, size: int, declared: int | None = None) -> None:
    """Add ``size`` deflated zeros to ``z`` (being written), declaring ``declared`` bytes."""
    payload, crc = _bomb(size)
    info = zipfile.ZipInfo(name)
    info.compress_type = zipfile.ZIP_DEFLATED
    info.CRC, info.compress_size = crc, len(payload)
    info.file_size = size if declared is None else declared
    fp = z.fp
    assert fp is not None
    info.header_offset = fp.tell()
    fp.write(info.FileHeader())
    fp.write(payload)
    z.filelist.append(info)
    z.NameToInfo[name] = info
    z.start_dir = fp.tell()  # type: ignore[attr-defined]


def _members(data: Path | bytes) -> list[tuple[zipfile.ZipInfo, bytes]]:
    """The members of a zip file, refusing (ValueError) one that expands beyond 50 MB."""
    source = io.BytesIO(data) if isinstance(data, bytes) else data
    members = []
    with zipfile.ZipFile(source) as archive:
        for info in archive.infolist():
            with archive.open(info) as fh:
                raw = fh.read(50_000_001)
            if len(raw) > 50_000_000 or info.file_size > 50_000_000:
                raise ValueError("an earlier mutation left a bomb")
            members.append((info, raw))
    return members


def _rewrite_zip(rng: random.Random, path: Path) -> str:
    members = _members(path)
    roll = rng.random()
    what = ""
    if roll < 0.2 and members:
        del members[rng.randrange(len(members))]
        what = "drop member"
    elif roll < 0.4:
        name = rng.choice(["evil.pth", "__init__.py", "../../x", "data", "policy.pth"])
        members.append((zipfile.ZipInfo(name), rng.choice([b"", b"\x80\x04N.", rng.randbytes(64)])))
        what = f"extra member {name}"
    elif roll < 0.7 and members:
        i = rng.randrange(len(members))
        info, raw = members[i]
        if info.filename.endswith(".pth") and rng.random() < 0.5:
            raw = _nested_bomb(raw, rng)
            what = f"bomb inside {info.filename}"
        elif rng.random() < 0.3:
            raw = b""  # replaced by a bomb below
            what = f"bomb {info.filename}"
        else:
            raw = bytearray(raw)
            for _ in range(rng.randrange(1, 5)):
                if raw:
                    raw[rng.randrange(len(raw))] = rng.randrange(256)
            raw = bytes(raw)
            what = f"corrupt {info.filename}"
        members[i] = (info, raw)
    lie = not what
    if lie:  # a member whose declared size lies: a deflate bomb declared tiny
        what = "lying bomb"
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as out:
        for info, raw in members:
            if what.startswith("bomb ") and what.endswith(info.filename) and not raw:
                _add_bomb(out, info.filename, rng.choice([64 << 20, 2000 << 20]))
            else:
                out.writestr(info.filename, raw)
        if lie:
            name = rng.choice(["policy.pth", "data", "q_table.npy", "metadata.npy", "extra"])
            name = name if name not in out.NameToInfo else name + "2"
            _add_bomb(out, name, rng.choice([64 << 20, 2000 << 20]), declared=100)
    return f"zip {path.name}: {what}"


def _nested_bomb(raw: bytes, rng: random.Random) -> bytes:
    """A torch archive (``raw``) with one record replaced by 1.5 GB of compressed zeros."""
    try:
        members = [(i.filename, data) for i, data in _members(raw)]
    except (zipfile.BadZipFile, ValueError, OSError, EOFError):
        return raw
    records = [k for k, (name, _) in enumerate(members) if "/data/" in name]
    if not records:
        return raw
    k = rng.choice(records)
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w") as z:
        for j, (name, data) in enumerate(members):
            if j == k:
                _add_bomb(z, name, 1500 << 20)
            else:
                z.writestr(name, data)
    return out.getvalue()


def mutate_zip(rng: random.Random, run: Path) -> str:
    files = [p for p in _files(run) if p.suffix in (".zip", ".npz")]
    if not files:
        return "zip: none"
    path = rng.choice(files)
    try:
        if path.suffix == ".npz" and rng.random() < 0.5:
            return _mutate_npz_metadata(rng, path)
        return _rewrite_zip(rng, path)
    except (zipfile.BadZipFile, zlib.error, OSError, ValueError, EOFError, KeyError) as exc:
        return f"zip {path.name}: unreadable ({type(exc).__name__})"


def _mutate_npz_metadata(rng: random.Random, path: Path) -> str:
    import numpy as np

    _members(path)  # not a bomb left by an earlier mutation
    with np.load(path, allow_pickle=False) as data:
        arrays = {k: np.array(data[k]) for k in data.files}
    meta = json.loads(str(arrays.get("metadata", "{}")))
    meta = _mutate_value(rng, meta)
    arrays["metadata"] = np.array(json.dumps(meta))
    if rng.random() < 0.3:
        name = rng.choice([k for k in arrays if k != "metadata"] or ["metadata"])
        arrays[name] = rng.choice([np.zeros(3), np.zeros((2, 2), np.int8), np.array("x")])
    with open(path, "wb") as fh:
        np.savez(fh, **arrays)
    return f"npz metadata {path.name}"


MUTATIONS: list[Callable[[random.Random, Path], str]] = [
    mutate_json,
    mutate_json,
    mutate_type,
    mutate_size,
    mutate_bytes,
    mutate_zip,
    mutate_zip,
]


def _commands(cli: str, out: Path) -> Callable[[Path], int]:
    if cli == "check":
        from aftir_rl.cli import check

        return lambda run: check.main([str(run)])
    if cli == "export":
        from aftir_rl.cli import export

        return lambda run: export.main([str(run), "-o", str(out / "x.json")])
    if cli == "demos":  # a Minari datasets root, as ``aftir train ppo --demos`` reads it
        from aftir_rl.cli.guard import cli as guarded
        from aftir_rl.rl.imitation import load_demos

        @guarded
        def demos(root: Path) -> int:
            load_demos(root / "aftir" / "armftl-expert-v0", gamma=0.99)
            return 0

        return demos
    if cli == "tank":  # a tank folder: tank.yaml naming the mesh files beside it
        from aftir_rl.cli import tank

        return lambda run: tank.main(["show", "--tank", str(run / "tank.yaml")])
    if cli == "view":
        from aftir_rl.cli import view

        return lambda run: view.main([str(run), "-o", str(out / "v.html")])
    if cli == "evaluate":
        from aftir_rl.cli import evaluate

        return lambda run: evaluate.main([str(run), "--logdir", str(out), "--no-progress"])
    if cli == "rollout":
        from aftir_rl.cli import rollout

        return lambda run: rollout.main([str(run), "--random", "1", "-o", str(out / "r")])
    spec = importlib.util.spec_from_file_location(
        "rank_checkpoints", Path(__file__).parents[1] / "benchmarks" / "rank_checkpoints.py"
    )
    module = importlib.util.module_from_spec(spec)  # type: ignore[arg-type]
    spec.loader.exec_module(module)  # type: ignore[union-attr]
    return lambda run: module.main([str(run), "--fresh", "2", "--corners", "1", "--extreme", "1"])


def memory_mb(field: str = "VmHWM") -> float:
    """This process's peak (``VmHWM``, since :func:`reset_peak`) or current (``VmRSS``) memory [MB].

    From ``/proc/self/status``, not ``getrusage``'s ``ru_maxrss``: that one keeps the peak of
    the process it was forked from (a pytest worker of 1 GB), and cannot be reset.
    """
    return _status_kb().get(field, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss) / 1024


def allocated_mb(peak: bool = True) -> float:
    """The memory this process allocated [MB]: resident, less the pages of mapped files.

    ``VmHWM`` (``peak``) or ``VmRSS``, less the current ``RssFile`` and ``RssShmem``: the
    shared libraries' code pages (torch's alone are over 100 MB) count in the resident size
    as far as the page cache maps them, which varies with how recently the files were written
    (the same command measured 107 or 165 MB at import in two checkouts of one machine, with
    the same 171 MB allocated). They are stable once the first case has loaded them.
    """
    status = _status_kb()
    total = status.get("VmHWM" if peak else "VmRSS", 0)
    return (total - status.get("RssFile", 0) - status.get("RssShmem", 0)) / 1024


def _status_kb() -> dict[str, int]:
    """The ``kB`` fields of ``/proc/self/status``."""
    out = {}
    for line in Path("/proc/self/status").read_text().splitlines():
        name, _, value = line.partition(":")
        if value.strip().endswith("kB"):
            out[name] = int(value.split()[0])
    return out


def reset_peak() -> None:
    """Restart ``VmHWM`` from the current resident size (Linux's ``clear_refs`` 5).

    What earlier cases freed is first handed back to the system (a collection, then glibc's
    ``malloc_trim``): a user's command starts in a fresh process, without their leftovers.
    """
    gc.collect()
    with contextlib.suppress(OSError, AttributeError):
        ctypes.CDLL("libc.so.6").malloc_trim(0)
    with contextlib.suppress(OSError):
        Path("/proc/self/clear_refs").write_text("5")


def _on_alarm(signum: int, frame: Any) -> None:
    raise Hang


def run_case(command: Callable[[Path], int], run: Path) -> tuple[Any, str, float]:
    """``(exit status or "hang"/"exception", stderr, seconds)`` of one case."""
    err, out = io.StringIO(), io.StringIO()
    start = time.perf_counter()
    signal.alarm(CASE_SECONDS)
    try:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(out):
            code: Any = command(run)
    except Hang:
        code = "hang"
    except BaseException:  # noqa: BLE001 (a traceback is the finding)
        code = "exception"
        err.write(traceback.format_exc())
    finally:
        signal.alarm(0)
    return code, err.getvalue(), time.perf_counter() - start


def warm(cli: str, workdir: str, sources: list[str]) -> int:
    """Run ``cli`` once on every source run as it is, unmeasured: numba compiles the kernels the
    command needs and caches them on disk, as a user's first command after installing does."""
    out = Path(workdir) / "out"
    out.mkdir(parents=True, exist_ok=True)
    command = _commands(cli, out)
    codes = [run_case(command, Path(source))[0] for source in sources]
    print(json.dumps({"cli": cli, "warm": codes}))
    return 0 if all(code == 0 for code in codes) else 1


def main(argv: list[str]) -> int:
    if argv[:1] == ["warm"]:  # ``python -m tests.fuzz warm CLI WORKDIR RUN_DIR...``
        return warm(argv[1], argv[2], argv[3:])
    cli, seed, cases, workdir, *sources = argv
    rng = random.Random(int(seed))
    work = Path(workdir)
    out = work / "out"
    out.mkdir(parents=True, exist_ok=True)
    signal.signal(signal.SIGALRM, _on_alarm)
    warnings.filterwarnings("ignore", "Duplicate name")
    command = _commands(cli, out)
    # One unmeasured run first: the libraries it maps stay, so that every case's file pages are
    # the same and :func:`allocated_mb` takes them off its peak (not only off its end).
    shutil.copytree(sources[0], work / "first", symlinks=True)
    run_case(command, work / "first")
    results = []
    for case in range(int(cases)):
        run = work / f"case{case}" / "run"
        shutil.copytree(rng.choice(sources), run, symlinks=True)
        done = [rng.choice(MUTATIONS)(rng, run) for _ in range(rng.choice([1, 1, 2, 3]))]
        reset_peak()
        before = round(allocated_mb(peak=False))
        code, err, seconds = run_case(command, run)
        allocated, resident = round(allocated_mb()), round(memory_mb())
        results.append(
            {"case": case, "code": code, "stderr": err, "s": seconds, "mut": done}
            | {"allocated": allocated, "before": before, "resident": resident}
        )
        shutil.rmtree(run.parent, ignore_errors=True)
    peak = max((case["allocated"] for case in results), default=0)
    print(json.dumps({"cli": cli, "peak_mb": peak, "results": results}))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
