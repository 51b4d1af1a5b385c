"""``aftir tank show | generate | export`` and ``--tank`` with a generated tank."""

from __future__ import annotations

import os
import stat

import pytest
import yaml

from aftir_rl.cli.tank import main
from aftir_rl.core.tank import load_tank


def test_generate_writes_a_tank_that_reads_back(tmp_path, capsys):
    out = tmp_path / "wing.yaml"
    assert main(["generate", "--kind", "wing", "--bays", "3", "--seed", "7", "-o", str(out)]) == 0
    tank = load_tank(out)
    assert len(tank.baffles) == 2 and tank.scene_dict() == load_tank("wing:3:7").scene_dict()
    assert yaml.safe_load(out.read_text())["name"] == "wing_3bay_s7"
    rounded = tmp_path / "round.yaml"  # the round family, the same tank as its spec
    assert main(["generate", "--kind", "round", "--seed", "6", "-o", str(rounded)]) == 0
    assert load_tank(rounded).scene_dict() == load_tank("round:3:6").scene_dict()
    assert yaml.safe_load(rounded.read_text())["name"] == "round_3bay_s6"


def test_show_takes_a_generator_spec_and_the_old_form(capsys):
    assert main(["show", "--tank", "wing:2:1"]) == 0
    assert "H hole in a baffle" in capsys.readouterr().out
    assert main(["--tank", "b737_center", "--json"]) == 0
    assert '"solids"' in capsys.readouterr().out


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["generate", "--bays", "0", "-o", "x.yaml"], "--bays must be from 1 to 8"),
        (["show", "--tank", "wing:0:1"], "unknown tank 'wing:0:1'"),
        (["export", "--tank", "b737_center", "-o", "tank.txt"], "expected a .stl, .obj, .ply file"),
    ],
)
def test_refusals_are_one_line(tmp_path, monkeypatch, capsys, argv, message):
    monkeypatch.chdir(tmp_path)
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err
    assert list(tmp_path.iterdir()) == []


def test_export_writes_a_mesh_and_a_tank_that_reads_it(tmp_path, capsys):
    pytest.importorskip("trimesh")
    assert main(["export", "--tank", "wing:2:4", "-o", str(tmp_path / "w.obj"), "--yaml",
                 str(tmp_path / "w.yaml")]) == 0  # fmt: skip
    meshed, tank = load_tank(tmp_path / "w.yaml"), load_tank("wing:2:4")
    assert (meshed.raster.obstructed == tank.raster.obstructed).all()
    assert "triangles" in capsys.readouterr().out


@pytest.mark.parametrize(
    ("obstacle", "content", "message"),
    [
        ({"type": "mesh", "file": "walls.stl"}, b"solid x\nendsolid x\n", "walls.stl"),
        ({"type": "mesh", "file": "../escape.stl"}, None, "leads out of the tank file's folder"),
        ({"type": "mesh", "file": "walls.txt"}, b"", "expected a .stl, .obj, .ply file"),
        ({"type": "mesh"}, None, "missing key 'file'"),
    ],
)
def test_hostile_mesh_tanks_are_one_line(tmp_path, capsys, obstacle, content, message):
    pytest.importorskip("trimesh")
    if content is not None:
        (tmp_path / obstacle["file"]).write_bytes(content)
    data = {"box": {"min": [-50, -50, 0], "max": [50, 50, 100]}, "obstacles": [obstacle]}
    (tmp_path / "t.yaml").write_text(yaml.safe_dump(data))
    assert main(["show", "--tank", str(tmp_path / "t.yaml")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err and "Traceback" not in err


def test_tour_draws_targets_in_any_bay_of_a_generated_tank(tmp_path, capsys):
    pytest.importorskip("toppra")
    from aftir_rl.cli.tour import main as tour

    out = tmp_path / "tour"
    assert tour(["--tank", "wing:2:1", "--random", "9", "--bay", "7", "-o", str(out)]) == 2
    assert "this tank has 2 bays" in capsys.readouterr().err and not out.exists()


def test_show_escapes_what_a_tank_file_says(tmp_path, capsys):
    """A name or description with terminal escapes (retitle, clear screen) prints as text."""
    path = tmp_path / "w.yaml"
    assert main(["generate", "--bays", "2", "--seed", "1", "-o", str(path)]) == 0
    data = yaml.safe_load(path.read_text())
    data["name"], data["description"] = "evil\x1b]0;pwned\x07", "x\x1b[2Jy"
    path.write_text(yaml.safe_dump(data))
    capsys.readouterr()
    assert main(["show", "--tank", str(path)]) == 0
    out = capsys.readouterr().out
    assert "\x1b" not in out and "\x07" not in out and "evil?]0;pwned?" in out


def test_outputs_never_replace_inputs_devices_or_each_other(tmp_path, capsys):
    tank = tmp_path / "w.yaml"
    assert main(["generate", "--bays", "2", "--seed", "1", "-o", str(tank)]) == 0
    before = tank.read_bytes()
    refusals = [
        ["generate", "--bays", "2", "--seed", "1", "-o", "/dev/full"],
        [
            "export",
            "--tank",
            str(tank),
            "-o",
            str(tmp_path / "a.stl"),
            "--walls",
            str(tmp_path / "a.stl"),
        ],
        ["export", "--tank", str(tank), "-o", str(tmp_path / "b.stl"), "--yaml", str(tank)],
    ]
    for argv in refusals:
        capsys.readouterr()
        assert main(argv) == 2
        assert capsys.readouterr().err.count("\n") == 1
    assert tank.read_bytes() == before and not (tmp_path / "a.stl").exists()
    assert stat.S_ISCHR(os.stat("/dev/full").st_mode)
