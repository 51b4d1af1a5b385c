"""Reading untrusted files: regular files only, bounded before reading; YAML bounded and strict."""

from __future__ import annotations

import os
import threading
import time
from pathlib import Path

import pytest

from aftir_rl.core.config import (
    CONFIG_DIR,
    MAX_YAML_BYTES,
    MAX_YAML_DEPTH,
    one_line,
    read_limited,
    read_yaml,
)
from aftir_rl.core.errors import CheckpointError, ConfigError
from aftir_rl.core.shipped import find_config, shipped_configs

# ------------------------------------------------------------------ read_limited


def _refused_promptly(path: Path) -> str:
    """The one-line message read_yaml gives for ``path``, failing the test if it blocks."""
    out: list[BaseException | None] = []

    def read() -> None:
        try:
            read_yaml(path)
            out.append(None)
        except BaseException as exc:  # noqa: BLE001 (handed to the test)
            out.append(exc)

    thread = threading.Thread(target=read, daemon=True)
    thread.start()
    thread.join(5)
    assert out, f"reading {path} blocked"
    assert isinstance(out[0], ConfigError), out[0]
    message = str(out[0])
    assert "\n" not in message
    return message


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs here")
def test_a_fifo_is_refused_without_blocking(tmp_path):
    fifo = tmp_path / "config.yaml"
    os.mkfifo(fifo)
    start = time.perf_counter()
    assert "not a regular file (a FIFO)" in _refused_promptly(fifo)
    assert time.perf_counter() - start < 1


@pytest.mark.skipif(not Path("/dev/zero").exists(), reason="no /dev/zero")
def test_a_device_is_refused():
    assert "not a regular file (a character device)" in _refused_promptly(Path("/dev/zero"))


def test_a_folder_is_refused(tmp_path):
    assert "not a regular file (a folder)" in _refused_promptly(tmp_path)


def test_a_missing_file_is_one_line(tmp_path):
    assert "cannot read the file" in _refused_promptly(tmp_path / "nope.yaml")


def test_a_large_sparse_file_is_refused_before_reading(tmp_path):
    sparse = tmp_path / "sparse.yaml"
    with sparse.open("wb") as fh:
        fh.truncate(50_000_000_000)  # 50 GB of nothing: refused from its size, never read
    start = time.perf_counter()
    assert f"larger than {MAX_YAML_BYTES:,} bytes" in _refused_promptly(sparse)
    assert time.perf_counter() - start < 0.5


def test_read_limited_reads_up_to_the_cap(tmp_path):
    path = tmp_path / "f"
    path.write_bytes(b"x" * 10)
    assert read_limited(path, 10, CheckpointError) == b"x" * 10
    with pytest.raises(CheckpointError, match="larger than 9 bytes; not a checkpoint"):
        read_limited(path, 9, CheckpointError, "checkpoint", "checkpoint")


def test_one_line():
    assert one_line("a\n  in 'b',\tposition 3\r\n") == "a in 'b', position 3"
    assert one_line("bell\x07 and escape\x1b[31m") == "bell? and escape?[31m"


# ------------------------------------------------------------------ YAML


def _yaml(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "c.yaml"
    path.write_text(text)
    return path


@pytest.mark.parametrize(
    "text, line, first",
    [
        ("tank: a\nepisodes: 5\nepisodes: 7\n", 3, 2),
        ("a: {x: 1, y: 2, x: 3}\n", 1, 1),
        ("a:\n  b:\n    - {k: 1}\n    - k: 1\n      k: 2\n", 5, 4),
        ("1: a\n1.0: b\n", 2, 1),
    ],
)
def test_a_repeated_key_is_refused_with_its_line(tmp_path, text, line, first):
    with pytest.raises(ConfigError, match=f"duplicate key .* on line {line} \\(first on line "):
        read_yaml(_yaml(tmp_path, text))
    with pytest.raises(ConfigError, match=f"first on line {first}\\)"):
        read_yaml(_yaml(tmp_path, text))


def test_merge_keys_are_not_repeats(tmp_path):
    text = "b: &b {x: 1, y: 1}\nc: &c {<<: *b, x: 2}\nd: {<<: [*c, *b], y: 3}\n"
    assert read_yaml(_yaml(tmp_path, text)) == {
        "b": {"x": 1, "y": 1},
        "c": {"x": 2, "y": 1},
        "d": {"x": 2, "y": 3},
    }


def _nested(depth: int, inner: str = "1") -> str:
    return "[" * depth + inner + "]" * depth


@pytest.mark.parametrize(
    "text",
    [
        "# " + "]" * 300 + "\na: " + _nested(199) + "\n",  # brackets in a comment do not count
        "a: " + _nested(100_000) + "\n",
        "a:\n" + "- " * 100_000 + "1\n",
        "a: &a " + _nested(40) + "\nb: " + _nested(40, "*a") + "\n",  # deep through an alias
        "a: " + _nested(MAX_YAML_DEPTH) + "\n",  # the mapping is one level more
    ],
)
def test_deep_nesting_is_refused_quickly(tmp_path, text):
    start = time.perf_counter()
    with pytest.raises(ConfigError, match="nested too deeply") as info:
        read_yaml(_yaml(tmp_path, text))
    assert time.perf_counter() - start < 1.5
    assert "\n" not in str(info.value)


def test_the_deepest_nesting_allowed_is_read(tmp_path):
    data = read_yaml(_yaml(tmp_path, "a: " + _nested(MAX_YAML_DEPTH - 1) + "\n"))
    assert data["a"] is not None


def test_a_recursive_alias_is_refused(tmp_path):
    with pytest.raises(ConfigError, match="alias inside its own anchor"):
        read_yaml(_yaml(tmp_path, "a: &a [1, *a]\n"))


def test_a_control_character_is_one_line_with_its_line(tmp_path):
    with pytest.raises(ConfigError) as info:
        read_yaml(_yaml(tmp_path, "tank: b737_center\nepisodes: 5\x01\n"))
    message = str(info.value)
    assert "\n" not in message and "(line 2): unacceptable character #x0001" in message


def test_a_yaml_syntax_error_is_one_line(tmp_path):
    with pytest.raises(ConfigError, match=r"not valid YAML \(line 3\)") as info:
        read_yaml(_yaml(tmp_path, "a: 1\nb: [1, 2\nc: 3\n"))
    assert "\n" not in str(info.value)


@pytest.mark.parametrize("name", ["ppo_ftl", "ppo_ftl.yaml", "configs/ppo_ftl.yaml"])
def test_a_shipped_config_is_found_by_name_from_anywhere(name, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # not the checkout: names, not paths
    assert find_config(name) == (CONFIG_DIR / "ppo_ftl.yaml").resolve()
    assert find_config("ppo", "search_spaces").parent.name == "search_spaces"


def test_a_path_wins_and_unknown_names_list_the_shipped(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "ppo_ftl.yaml").write_text("env_id: AFTIR-ArmReach-v0\n")
    assert find_config("ppo_ftl.yaml") == Path("ppo_ftl.yaml")
    for name in ("nope", "../configs/ppo", "/etc/passwd.yaml", ""):
        with pytest.raises(ConfigError, match="no shipped config of that name; shipped: ppo_ftl,"):
            find_config(name)
    assert "tanks/b737_center" in shipped_configs() and "ppo_ftl" in shipped_configs()


def test_aftir_configs_lists_them(capsys):
    from aftir_rl.cli import configs

    assert configs.main(["tanks"]) == 0
    out = capsys.readouterr().out
    assert "b737_center" in out and "Boeing 737" in out
