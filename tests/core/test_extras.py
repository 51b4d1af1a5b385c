"""Without an optional dependency, what needs it says which extra to install, in one line."""

from __future__ import annotations

import subprocess
import sys

import pytest


def _python(code: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)


@pytest.mark.parametrize(
    "blocked,call,extra",
    [
        (
            "plotly",
            "from aftir_rl.viz.page import write_view; write_view(['runs/x'], 'v.html')",
            "view",
        ),
        (
            "ompl",
            "from aftir_rl.planning.jointspace import rrt_connect\n"
            "from aftir_rl.core.collision import CollisionScene\n"
            "from aftir_rl.core.robot import Posture\n"
            "from aftir_rl.core.tank import load_tank\n"
            "t = load_tank('open_space'); p = Posture(0.0, [0.0], [0.0])\n"
            "rrt_connect(CollisionScene(t, t.arm), p, p)",
            "ompl",
        ),
        (
            "elastica",
            "from aftir_rl.experiments.physics import RodModel\n"
            "from aftir_rl.core.rod import RodProperties\n"
            "RodModel(2, 50.0, 2.5, RodProperties())",
            "physics",
        ),
        (
            "trimesh",
            "from aftir_rl.core.tank import load_tank\n"
            "from aftir_rl.core.tank.meshes import export_tank_mesh\n"
            "export_tank_mesh(load_tank('b737_center'), 'never.stl')",
            "mesh",
        ),
    ],
)
def test_missing_extra_is_a_catchable_one_line_error(blocked, call, extra):
    code = (
        f"import sys; sys.modules[{blocked!r}] = None\n"
        "from aftir_rl.core.errors import MissingExtraError\n"
        "try:\n"
        + "".join(f"    {line}\n" for line in call.splitlines())
        + "except MissingExtraError as exc:\n    print(exc)\n"
    )
    out = _python(code)
    assert out.returncode == 0, out.stderr
    assert f'pip install "aftir_rl[{extra}]"' in out.stdout


def test_view_without_plotly_exits_2(tmp_path):
    code = (
        "import sys; sys.modules['plotly'] = None\n"
        "from aftir_rl.cli.view import main\n"
        f"sys.exit(main([{str(tmp_path)!r}, '-o', {str(tmp_path / 'v.html')!r}]))"
    )
    out = _python(code)
    assert out.returncode == 2
    assert out.stderr.strip().count("\n") == 0 and "aftir_rl[view]" in out.stderr
    assert not (tmp_path / "v.html").exists()


def test_simulate_without_pyelastica_exits_2_and_writes_nothing(tmp_path):
    (tmp_path / "trajectory.json").write_text("{}")
    code = (
        "import sys; sys.modules['elastica'] = None\n"
        "from aftir_rl.cli.simulate import main\n"
        f"sys.exit(main([{str(tmp_path)!r}]))"
    )
    out = _python(code)
    assert out.returncode == 2, out.stderr
    assert out.stderr.strip().count("\n") == 0 and "aftir_rl[physics]" in out.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["trajectory.json"]


def test_bench_without_ompl_stops_before_any_work():
    code = (
        "import sys; sys.modules['ompl'] = None\n"
        "import numpy as np\n"
        "from aftir_rl.core.errors import MissingExtraError\n"
        "from aftir_rl.experiments.bench import run_benchmark\n"
        "calls = []\n"
        "try:\n"
        "    run_benchmark({'s': [('b737_center', np.array([20.0, 10.0, 60.0]))]},\n"
        "                  methods={'s': ['tga', 'rrt_connect']}, progress=calls.append)\n"
        "except MissingExtraError as exc:\n"
        "    print(len(calls), exc)\n"
    )
    out = _python(code)
    assert out.returncode == 0, out.stderr
    assert out.stdout.startswith("0 ") and "aftir_rl[ompl]" in out.stdout
